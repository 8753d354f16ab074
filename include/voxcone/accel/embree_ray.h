#pragma once
/// \file embree_ray.h
/// A voxcone Ray as Embree 3's RTCRay, for `--accel embree` (embree_accel.cpp) and the HBVH's
/// benchmark against Embree (bench/hbvh_vs_embree.cpp). Include only where Embree is linked.

#include "voxcone/core/ray.h"

#include <embree3/rtcore.h>

namespace voxcone {

/// `r` as an RTCRay searching (r.tMin, tMax).
inline void toEmbree(const Ray& r, float tMax, RTCRay& out) {
  out.org_x = r.origin.x;
  out.org_y = r.origin.y;
  out.org_z = r.origin.z;
  out.tnear = r.tMin;
  out.dir_x = r.dir.x;
  out.dir_y = r.dir.y;
  out.dir_z = r.dir.z;
  out.time = 0.0f;
  out.tfar = tMax;
  out.mask = 0xffffffffu;
  out.id = 0;
  out.flags = 0;
}

}  // namespace voxcone

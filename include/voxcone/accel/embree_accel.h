#pragma once
/// \file embree_accel.h
/// Embree 3 behind the Accel interface (`--accel embree`, built where libembree-dev is found):
/// so that the structures study and any render compare the HBVH with Embree in the same image,
/// not only in bench/hbvh_vs_embree. One triangle geometry, RTC_BUILD_QUALITY_MEDIUM, Embree's
/// default (non-robust) rtcIntersect1 / rtcOccluded1. Not watertight: a ray through a shared
/// edge may slip between its triangles, which the HBVH's test never lets happen.

#include "voxcone/accel/accel.h"

#include <memory>

namespace voxcone {

/// True when this build has Embree (VOXCONE_HAVE_EMBREE).
bool embreeAvailable();

/// Embree's BVH over the triangles (world space). Triangles with an index out of range or a
/// vertex that is not finite are left out, as every structure does. SettingsError when this
/// build has no Embree; Error when Embree fails.
std::unique_ptr<Accel> buildEmbreeAccel(const std::vector<Vec3>& positions, const std::vector<UVec3>& triangles,
                                        Progress* progress = nullptr);

}  // namespace voxcone

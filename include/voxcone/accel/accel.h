#pragma once
/// \file accel.h
/// What the renderer asks of a ray acceleration structure: the closest hit and any hit. The
/// HBVH (hbvh.h) is the default; a plain AABB BVH (the same builder with no spheres) and an SAH
/// kd-tree (kdtree.h) exist for the structures study. Integrators see only this interface
/// (as pbrt's Primitive / Embree's RTCScene): one virtual call per ray.

#include "voxcone/core/bounds.h"
#include "voxcone/core/progress.h"
#include "voxcone/core/ray.h"

#include <nlohmann/json_fwd.hpp>

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace voxcone {

class Scene;
struct SurfaceHit;

/// A ray hit: distance along the ray (units of |dir|), triangle id, barycentrics of v1 and v2.
struct Hit {
  float t = kInf;
  uint32_t triangle = 0;
  float b1 = 0.0f, b2 = 0.0f;
};

class Accel {
public:
  virtual ~Accel() = default;
  /// Closest hit in (ray.tMin, ray.tMax), or nothing.
  virtual std::optional<Hit> intersect(const Ray& ray) const = 0;
  /// True when anything is hit in (ray.tMin, tMax).
  virtual bool occluded(const Ray& ray, float tMax) const = 0;
  bool occluded(const Ray& ray) const { return occluded(ray, ray.tMax); }
  virtual Bounds3 bounds() const = 0;

  /// "hbvh", "bvh" or "kdtree".
  virtual std::string kind() const = 0;
  /// Memory of nodes and triangle data (not the scene's own mesh).
  virtual uint64_t bytes() const = 0;
  virtual double buildSeconds() const = 0;
  /// Statistics for sidecars and `voxcone info`; always has "kind", "bytes", "build_seconds".
  virtual nlohmann::json statsJson() const = 0;
};

/// The structures `buildAccel` knows, default first.
const std::vector<std::string>& accelKinds();
/// Build the named structure over the scene's triangles; SettingsError for an unknown kind.
std::unique_ptr<Accel> buildAccel(const std::string& kind, const Scene& scene, Progress* progress = nullptr);
std::unique_ptr<Accel> buildAccel(const std::string& kind, const std::vector<Vec3>& positions,
                                  const std::vector<UVec3>& triangles, Progress* progress = nullptr);

/// The surface `ray` hits first: Scene::surfaceAt at accel's closest hit. False when it hits
/// nothing (out is left alone).
bool intersectSurface(const Scene& scene, const Accel& accel, const Ray& ray, SurfaceHit& out);

}  // namespace voxcone

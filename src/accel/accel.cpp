// The structures behind the Accel interface, by name.

#include "voxcone/accel/accel.h"

#include "voxcone/accel/embree_accel.h"
#include "voxcone/accel/hbvh.h"
#include "voxcone/accel/kdtree.h"
#include "voxcone/core/error.h"
#include "voxcone/scene/scene.h"

namespace voxcone {

#ifndef VOXCONE_HAVE_EMBREE
bool embreeAvailable() { return false; }

std::unique_ptr<Accel> buildEmbreeAccel(const std::vector<Vec3>&, const std::vector<UVec3>&, Progress*) {
  throw SettingsError("this voxcone was built without Embree (install libembree-dev and rebuild)");
}
#endif

const std::vector<std::string>& accelKinds() {
  static const std::vector<std::string> kinds = [] {
    std::vector<std::string> k = {"hbvh", "bvh", "kdtree"};
    if (embreeAvailable()) k.push_back("embree");
    return k;
  }();
  return kinds;
}

std::unique_ptr<Accel> buildAccel(const std::string& kind, const std::vector<Vec3>& positions,
                                  const std::vector<UVec3>& triangles, Progress* progress) {
  if (kind == "hbvh") return std::make_unique<Hbvh>(positions, triangles, HbvhBuildSettings{}, progress);
  if (kind == "bvh") {
    HbvhBuildSettings s;
    s.sphereAreaRatio = 0.0f;
    return std::make_unique<Hbvh>(positions, triangles, s, progress);
  }
  if (kind == "kdtree") return std::make_unique<KdTree>(positions, triangles, KdTreeBuildSettings{}, progress);
  if (kind == "embree" && embreeAvailable()) return buildEmbreeAccel(positions, triangles, progress);
  std::string names;
  for (const std::string& k : accelKinds()) names += (names.empty() ? "" : ", ") + k;
  throw SettingsError("unknown acceleration structure '" + kind + "' (one of " + names + ")");
}

std::unique_ptr<Accel> buildAccel(const std::string& kind, const Scene& scene, Progress* progress) {
  return buildAccel(kind, scene.positions, scene.triangles, progress);
}

bool intersectSurface(const Scene& scene, const Accel& accel, const Ray& ray, SurfaceHit& out) {
  const std::optional<Hit> hit = accel.intersect(ray);
  if (!hit) return false;
  out = scene.surfaceAt(hit->triangle, hit->b1, hit->b2);
  return true;
}

}  // namespace voxcone

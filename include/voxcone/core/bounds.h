#pragma once
/// \file bounds.h
/// Axis-aligned bounding boxes and bounding spheres in world space.

#include "voxcone/core/math.h"

namespace voxcone {

/// Axis-aligned box; an empty box has lo = +inf, hi = -inf.
struct Bounds3 {
  Vec3 lo{kInf};
  Vec3 hi{-kInf};

  Bounds3() = default;
  Bounds3(const Vec3& a, const Vec3& b) : lo(glm::min(a, b)), hi(glm::max(a, b)) {}

  bool empty() const { return lo.x > hi.x || lo.y > hi.y || lo.z > hi.z; }
  void extend(const Vec3& p) { lo = glm::min(lo, p); hi = glm::max(hi, p); }
  void extend(const Bounds3& b) { lo = glm::min(lo, b.lo); hi = glm::max(hi, b.hi); }
  Vec3 diagonal() const { return hi - lo; }
  Vec3 center() const { return 0.5f * (lo + hi); }
  /// Surface area (mm^2 in scene units); 0 for an empty box.
  float area() const {
    if (empty()) return 0.0f;
    const Vec3 d = diagonal();
    return 2.0f * (d.x * d.y + d.y * d.z + d.z * d.x);
  }
  bool contains(const Vec3& p) const {
    return p.x >= lo.x && p.y >= lo.y && p.z >= lo.z && p.x <= hi.x && p.y <= hi.y && p.z <= hi.z;
  }
};

inline Bounds3 unite(const Bounds3& a, const Bounds3& b) {
  Bounds3 r = a;
  r.extend(b);
  return r;
}

/// Bounding sphere (centre, radius) in world space.
struct Sphere {
  Vec3 center{0.0f};
  float radius = -1.0f;  ///< negative when unset
  float area() const { return radius < 0.0f ? 0.0f : 4.0f * kPi * radius * radius; }
};

}  // namespace voxcone

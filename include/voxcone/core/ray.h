#pragma once
/// \file ray.h
/// Rays in world space and robust spawn offsets.

#include "voxcone/core/math.h"

#include <cstring>

namespace voxcone {

/// A ray o + t d for t in [tMin, tMax]; d need not be normalized (t is in units of |d|).
struct Ray {
  Vec3 origin{0.0f};
  Vec3 dir{0.0f, 0.0f, 1.0f};
  float tMin = 0.0f;
  float tMax = kInf;
  Vec3 at(float t) const { return origin + t * dir; }
};

/// Offset a surface point along the geometric normal, on the side of `dir`, far enough that a
/// ray leaving it does not hit the surface it left. The offset scales with the magnitude of the
/// point's coordinates, because float rounding of a hit point grows with them (the
/// error-bound-free variant of Wächter & Binder, "A Fast and Robust Method for Avoiding
/// Self-Intersection", Ray Tracing Gems ch. 6): integer-ULP steps in the normal direction.
inline Vec3 offsetRayOrigin(const Vec3& p, const Vec3& geomNormal, const Vec3& dir) {
  constexpr float kOrigin = 1.0f / 32.0f;
  constexpr float kFloatScale = 1.0f / 65536.0f;
  constexpr float kIntScale = 256.0f;
  Vec3 n = glm::dot(geomNormal, dir) < 0.0f ? -geomNormal : geomNormal;
  Vec3 out;
  for (int i = 0; i < 3; ++i) {
    const int offI = static_cast<int>(kIntScale * n[i]);
    int bits;
    std::memcpy(&bits, &p[i], sizeof(float));
    bits += (p[i] < 0.0f) ? -offI : offI;
    float pI;
    std::memcpy(&pI, &bits, sizeof(float));
    out[i] = std::fabs(p[i]) < kOrigin ? p[i] + kFloatScale * n[i] : pI;
  }
  return out;
}

/// A ray leaving surface point p (geometric normal ng) in direction d.
inline Ray spawnRay(const Vec3& p, const Vec3& ng, const Vec3& d) {
  Ray r;
  r.origin = offsetRayOrigin(p, ng, d);
  r.dir = d;
  return r;
}

/// A ray from surface point p towards point target, stopping just short of it.
inline Ray spawnRayTo(const Vec3& p, const Vec3& ng, const Vec3& target) {
  Ray r;
  r.origin = offsetRayOrigin(p, ng, target - p);
  r.dir = target - r.origin;
  r.tMax = 1.0f - 1e-4f;
  return r;
}

}  // namespace voxcone

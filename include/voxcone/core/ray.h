#pragma once
/// \file ray.h
/// Rays in world space, floating-point error bounds of surface points, and ray spawning that
/// never re-hits the surface it leaves.
///
/// The scheme is the one of Pharr, Jakob & Humphreys, "Physically Based Rendering" (4th ed.),
/// section 6.8 "Managing Rounding Error": (1) a hit point is computed from its barycentrics,
/// with a conservative bound on its rounding error per axis (barycentricPoint); (2) a spawned
/// ray starts at that point pushed along the geometric normal by the bound's extent in that
/// direction, rounded away from the surface (offsetRayOrigin), so the origin lies on the side
/// the ray leaves to; (3) the ray-triangle test rejects hits whose distance is not
/// conservatively positive (triangle.h), which removes re-hits the origin's side alone cannot,
/// since the test's own error scales with the triangle's extent, not with the point's
/// coordinates. All three are needed; none is a tuned epsilon.

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

/// Unit roundoff of float (half an ulp of 1).
constexpr float kMachineEpsilon = 0x1p-24f;

/// Higham's gamma_n = n u / (1 - n u): the relative error bound of n chained float operations.
constexpr float errorGamma(int n) { return (float(n) * kMachineEpsilon) / (1.0f - float(n) * kMachineEpsilon); }

/// The next float above v (towards +inf); +inf and NaN are returned unchanged, -0 becomes the
/// smallest positive denormal.
inline float nextFloatUp(float v) {
  if (std::isinf(v) && v > 0.0f) return v;
  if (v == -0.0f) v = 0.0f;
  uint32_t bits;
  std::memcpy(&bits, &v, sizeof(float));
  bits = v >= 0.0f ? bits + 1 : bits - 1;
  std::memcpy(&v, &bits, sizeof(float));
  return v;
}

/// The next float below v (towards -inf).
inline float nextFloatDown(float v) {
  if (std::isinf(v) && v < 0.0f) return v;
  if (v == 0.0f) v = -0.0f;
  uint32_t bits;
  std::memcpy(&bits, &v, sizeof(float));
  bits = v > 0.0f ? bits - 1 : bits + 1;
  std::memcpy(&v, &bits, sizeof(float));
  return v;
}

/// b0 p0 + b1 p1 + b2 p2 in float, and in `errorOut` a bound on its absolute rounding error per
/// axis: each coordinate is three products and two sums, at most gamma(7) times the sum of the
/// terms' magnitudes (PBRT 4th ed., eq. 6.30 for triangle hit points).
inline Vec3 barycentricPoint(const Vec3& p0, const Vec3& p1, const Vec3& p2, float b0, float b1, float b2,
                             Vec3& errorOut) {
  const Vec3 t0 = b0 * p0, t1 = b1 * p1, t2 = b2 * p2;
  errorOut = errorGamma(7) * (glm::abs(t0) + glm::abs(t1) + glm::abs(t2));
  return t0 + t1 + t2;
}

/// Surface point p (rounding error at most `pError` per axis, geometric normal ng) moved off
/// the surface to the side of `dir`: along ng by the error box's extent in that direction, then
/// rounded one ulp further away, so the result lies strictly on that side of the exact surface
/// (PBRT 4th ed., section 6.8.6).
inline Vec3 offsetRayOrigin(const Vec3& p, const Vec3& pError, const Vec3& geomNormal, const Vec3& dir) {
  const float d = glm::dot(glm::abs(geomNormal), pError);
  Vec3 offset = d * geomNormal;
  if (glm::dot(dir, geomNormal) < 0.0f) offset = -offset;
  Vec3 out = p + offset;
  for (int i = 0; i < 3; ++i) {
    if (offset[i] > 0.0f) out[i] = nextFloatUp(out[i]);
    else if (offset[i] < 0.0f) out[i] = nextFloatDown(out[i]);
  }
  return out;
}

/// A ray leaving surface point p (error bound pError, geometric normal ng) in direction d.
inline Ray spawnRay(const Vec3& p, const Vec3& pError, const Vec3& ng, const Vec3& d) {
  Ray r;
  r.origin = offsetRayOrigin(p, pError, ng, d);
  r.dir = d;
  return r;
}

/// Shadow rays stop this fraction of their length short of the target, so the light or
/// surface sampled there is not itself an occluder (PBRT's ShadowEpsilon).
constexpr float kShadowEpsilon = 1e-4f;

/// A ray from surface point p towards a point `target` on another surface (error bound
/// targetError, normal targetNormal; zero for a point light), both ends offset off their
/// surfaces towards each other; it stops kShadowEpsilon short of the offset target.
inline Ray spawnRayTo(const Vec3& p, const Vec3& pError, const Vec3& ng, const Vec3& target,
                      const Vec3& targetError = Vec3(0.0f), const Vec3& targetNormal = Vec3(0.0f)) {
  Ray r;
  r.origin = offsetRayOrigin(p, pError, ng, target - p);
  const Vec3 end = offsetRayOrigin(target, targetError, targetNormal, r.origin - target);
  r.dir = end - r.origin;
  r.tMax = 1.0f - kShadowEpsilon;
  return r;
}

}  // namespace voxcone

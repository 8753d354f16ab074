#pragma once
/// \file sampling.h
/// Warping [0,1)^2 to directions and shapes, with their densities (pbrt-v4, ch. A.5).

#include "voxcone/core/math.h"

namespace voxcone {

/// Concentric map of the square onto the unit disk (Shirley & Chiu 1997).
inline Vec2 sampleConcentricDisk(const Vec2& u) {
  const Vec2 uo = 2.0f * u - Vec2(1.0f);
  if (uo.x == 0.0f && uo.y == 0.0f) return Vec2(0.0f);
  float r, theta;
  if (std::fabs(uo.x) > std::fabs(uo.y)) {
    r = uo.x;
    theta = 0.25f * kPi * (uo.y / uo.x);
  } else {
    r = uo.y;
    theta = 0.5f * kPi - 0.25f * kPi * (uo.x / uo.y);
  }
  return r * Vec2(std::cos(theta), std::sin(theta));
}

/// Cosine-weighted direction on the +z hemisphere (Malley's method); pdf cos(theta)/pi.
inline Vec3 sampleCosineHemisphere(const Vec2& u) {
  const Vec2 d = sampleConcentricDisk(u);
  const float z = safeSqrt(1.0f - d.x * d.x - d.y * d.y);
  return Vec3(d.x, d.y, z);
}
inline float cosineHemispherePdf(float cosTheta) { return std::max(0.0f, cosTheta) * kInvPi; }

/// Uniform direction on the unit sphere; pdf 1/(4 pi).
inline Vec3 sampleUniformSphere(const Vec2& u) {
  const float z = 1.0f - 2.0f * u.x;
  const float r = safeSqrt(1.0f - z * z);
  const float phi = 2.0f * kPi * u.y;
  return Vec3(r * std::cos(phi), r * std::sin(phi), z);
}
constexpr float kUniformSpherePdf = 1.0f / (4.0f * kPi);

/// Uniform direction in the cone about +z of half-angle theta, given 1 - cos theta (without
/// cancellation for small cones); pdf 1 / (2 pi (1 - cos theta)).
inline Vec3 sampleUniformCone(const Vec2& u, float oneMinusCos) {
  const float z = 1.0f - u.y * oneMinusCos;
  const float r = safeSqrt(1.0f - z * z);
  const float phi = 2.0f * kPi * u.x;
  return Vec3(r * std::cos(phi), r * std::sin(phi), z);
}

/// Uniform barycentrics (b1, b2) on a triangle (Heitz 2019, "A Low-Distortion Map Between
/// Triangle and Square").
inline Vec2 sampleUniformTriangle(const Vec2& u) {
  float b0, b1;
  if (u.x < u.y) {
    b0 = u.x / 2;
    b1 = u.y - b0;
  } else {
    b1 = u.y / 2;
    b0 = u.x - b1;
  }
  return Vec2(b0, b1);
}

/// Veach's power heuristic (beta = 2) for multiple importance sampling.
inline float powerHeuristic(float pdfA, float pdfB) {
  const float a = pdfA * pdfA;
  const float b = pdfB * pdfB;
  if (std::isinf(a)) return 1.0f;
  return (a + b) > 0.0f ? a / (a + b) : 0.0f;
}

}  // namespace voxcone

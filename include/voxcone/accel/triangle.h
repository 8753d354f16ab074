#pragma once
/// \file triangle.h
/// Watertight ray-triangle intersection (Woop, Benthin & Wald 2013, "Watertight Ray/Triangle
/// Intersection", JCGT 2(1)): rays through shared edges and vertices hit exactly one of the
/// triangles, never fall through a crack.

#include "voxcone/core/ray.h"

namespace voxcone {

/// Per-ray constants of the watertight test: the axis permutation and shear.
struct WatertightRay {
  int kx, ky, kz;
  float sx, sy, sz;
  explicit WatertightRay(const Vec3& dir) {
    // kz: dimension where the direction is largest in magnitude; swap kx,ky to keep winding.
    const Vec3 a = glm::abs(dir);
    kz = maxDimension(a);
    kx = kz == 2 ? 0 : kz + 1;
    ky = kx == 2 ? 0 : kx + 1;
    if (dir[kz] < 0.0f) std::swap(kx, ky);
    sx = dir[kx] / dir[kz];
    sy = dir[ky] / dir[kz];
    sz = 1.0f / dir[kz];
  }
};

/// Test ray (origin, wr) against triangle (p0, p1, p2) for t in (tMin, tMax). On a hit writes t
/// and barycentrics (b1, b2) of p1 and p2 and returns true. Both sides hit.
inline bool intersectTriangleWatertight(const Vec3& origin, const WatertightRay& wr, const Vec3& p0,
                                        const Vec3& p1, const Vec3& p2, float tMin, float tMax, float& tOut,
                                        float& b1Out, float& b2Out) {
  // Vertices relative to the origin, permuted and sheared so the ray is +z through (0,0).
  const Vec3 A = p0 - origin, B = p1 - origin, C = p2 - origin;
  const float ax = A[wr.kx] - wr.sx * A[wr.kz], ay = A[wr.ky] - wr.sy * A[wr.kz];
  const float bx = B[wr.kx] - wr.sx * B[wr.kz], by = B[wr.ky] - wr.sy * B[wr.kz];
  const float cx = C[wr.kx] - wr.sx * C[wr.kz], cy = C[wr.ky] - wr.sy * C[wr.kz];
  // Scaled barycentrics: 2D edge functions.
  float u = cx * by - cy * bx;
  float v = ax * cy - ay * cx;
  float w = bx * ay - by * ax;
  // Exactly zero: recompute in double so that edges are decided consistently (the paper's
  // fallback for watertightness).
  if (u == 0.0f || v == 0.0f || w == 0.0f) {
    u = static_cast<float>(double(cx) * double(by) - double(cy) * double(bx));
    v = static_cast<float>(double(ax) * double(cy) - double(ay) * double(cx));
    w = static_cast<float>(double(bx) * double(ay) - double(by) * double(ax));
  }
  if ((u < 0.0f || v < 0.0f || w < 0.0f) && (u > 0.0f || v > 0.0f || w > 0.0f)) return false;
  const float det = u + v + w;
  if (det == 0.0f) return false;
  // Scaled hit distance, compared against the range before dividing.
  const float az = wr.sz * A[wr.kz], bz = wr.sz * B[wr.kz], cz = wr.sz * C[wr.kz];
  const float tScaled = u * az + v * bz + w * cz;
  if (det < 0.0f ? (tScaled >= tMin * det || tScaled <= tMax * det) : (tScaled <= tMin * det || tScaled >= tMax * det))
    return false;
  const float invDet = 1.0f / det;
  tOut = tScaled * invDet;
  b1Out = v * invDet;
  b2Out = w * invDet;
  return true;
}

}  // namespace voxcone

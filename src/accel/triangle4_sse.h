#pragma once
// The watertight ray-triangle test (triangle.h) on a Triangle4 packet with SSE, shared by the
// HBVH's and the kd-tree's leaves.

#include "voxcone/accel/accel.h"
#include "voxcone/accel/triangle.h"

#include <smmintrin.h>

namespace voxcone {

/// Per-ray constants of the 4-wide watertight test: the scalar shear, broadcast.
struct RayTri4 {
  WatertightRay wr;
  __m128 org[3];
  __m128 sx, sy, sz;
  explicit RayTri4(const Ray& r) : wr(r.dir) {
    for (int a = 0; a < 3; ++a) org[a] = _mm_set1_ps(r.origin[a]);
    sx = _mm_set1_ps(wr.sx);
    sy = _mm_set1_ps(wr.sy);
    sz = _mm_set1_ps(wr.sz);
  }
};

/// The watertight test (triangle.h) on four triangles at once, with the same operations in the
/// same order as the scalar test, so both give the same t. Lanes where an edge function is
/// exactly zero are redone by the scalar test, which resolves them in double precision.
/// Returns the mask of lanes hit in (tMin, tMax) and their t and barycentrics.
inline int intersectTriangle4(const Triangle4& tri, const Ray& ray, const RayTri4& rt, float tMin, float tMax,
                              float tOut[4], float b1Out[4], float b2Out[4]) {
  const int kx = rt.wr.kx, ky = rt.wr.ky, kz = rt.wr.kz;
  __m128 px[3], py[3], pz[3];  // per vertex: sheared x, y and the unsheared z coordinate
  for (int vtx = 0; vtx < 3; ++vtx) {
    const __m128 x = _mm_sub_ps(_mm_load_ps(tri.v[vtx][kx]), rt.org[kx]);
    const __m128 y = _mm_sub_ps(_mm_load_ps(tri.v[vtx][ky]), rt.org[ky]);
    pz[vtx] = _mm_sub_ps(_mm_load_ps(tri.v[vtx][kz]), rt.org[kz]);
    px[vtx] = _mm_sub_ps(x, _mm_mul_ps(rt.sx, pz[vtx]));
    py[vtx] = _mm_sub_ps(y, _mm_mul_ps(rt.sy, pz[vtx]));
  }
  // Scaled barycentrics: 2D edge functions (A = vertex 0, B = 1, C = 2).
  const __m128 u = _mm_sub_ps(_mm_mul_ps(px[2], py[1]), _mm_mul_ps(py[2], px[1]));
  const __m128 v = _mm_sub_ps(_mm_mul_ps(px[0], py[2]), _mm_mul_ps(py[0], px[2]));
  const __m128 w = _mm_sub_ps(_mm_mul_ps(px[1], py[0]), _mm_mul_ps(py[1], px[0]));
  const __m128 zero = _mm_setzero_ps();
  const int zeroLanes = _mm_movemask_ps(
      _mm_or_ps(_mm_or_ps(_mm_cmpeq_ps(u, zero), _mm_cmpeq_ps(v, zero)), _mm_cmpeq_ps(w, zero)));
  // Inside when all three share a sign; NaN lanes (padding) compare false everywhere.
  const __m128 allPos = _mm_and_ps(_mm_and_ps(_mm_cmpge_ps(u, zero), _mm_cmpge_ps(v, zero)), _mm_cmpge_ps(w, zero));
  const __m128 allNeg = _mm_and_ps(_mm_and_ps(_mm_cmple_ps(u, zero), _mm_cmple_ps(v, zero)), _mm_cmple_ps(w, zero));
  const __m128 det = _mm_add_ps(_mm_add_ps(u, v), w);
  __m128 valid = _mm_and_ps(_mm_or_ps(allPos, allNeg), _mm_cmpneq_ps(det, zero));
  // Scaled distance compared against the range before dividing; |det| and the sign-flipped
  // distance replace the scalar test's two branches.
  const __m128 tScaled = _mm_add_ps(_mm_add_ps(_mm_mul_ps(u, _mm_mul_ps(rt.sz, pz[0])), _mm_mul_ps(v, _mm_mul_ps(rt.sz, pz[1]))),
                                    _mm_mul_ps(w, _mm_mul_ps(rt.sz, pz[2])));
  const __m128 signMask = _mm_set1_ps(-0.0f);
  const __m128 detSign = _mm_and_ps(det, signMask);
  const __m128 detAbs = _mm_xor_ps(det, detSign);
  const __m128 tAbs = _mm_xor_ps(tScaled, detSign);
  valid = _mm_and_ps(valid, _mm_cmpgt_ps(tAbs, _mm_mul_ps(_mm_set1_ps(tMin), detAbs)));
  valid = _mm_and_ps(valid, _mm_cmplt_ps(tAbs, _mm_mul_ps(_mm_set1_ps(tMax), detAbs)));
  int mask = _mm_movemask_ps(valid) & ~zeroLanes;
  if (mask) {
    const __m128 invDet = _mm_div_ps(_mm_set1_ps(1.0f), det);
    const __m128 t = _mm_mul_ps(tScaled, invDet);
    // Only distances above their own rounding error (watertightDistanceError, lane by lane).
    const auto abs4 = [&](__m128 a) { return _mm_andnot_ps(signMask, a); };
    const auto max3 = [&](__m128 a, __m128 b, __m128 c) { return _mm_max_ps(abs4(a), _mm_max_ps(abs4(b), abs4(c))); };
    const __m128 maxZ = _mm_mul_ps(max3(pz[0], pz[1], pz[2]), abs4(rt.sz));
    const __m128 maxX = max3(px[0], px[1], px[2]);
    const __m128 maxY = max3(py[0], py[1], py[2]);
    const __m128 maxE = max3(u, v, w);
    const __m128 g2 = _mm_set1_ps(errorGamma(2)), g3 = _mm_set1_ps(errorGamma(3)), g5 = _mm_set1_ps(errorGamma(5));
    const __m128 deltaZ = _mm_mul_ps(g3, maxZ);
    const __m128 deltaX = _mm_mul_ps(g5, _mm_add_ps(maxX, maxZ));
    const __m128 deltaY = _mm_mul_ps(g5, _mm_add_ps(maxY, maxZ));
    const __m128 deltaE = _mm_mul_ps(
        _mm_set1_ps(2.0f), _mm_add_ps(_mm_add_ps(_mm_mul_ps(g2, _mm_mul_ps(maxX, maxY)), _mm_mul_ps(deltaY, maxX)),
                                      _mm_mul_ps(deltaX, maxY)));
    const __m128 deltaT = _mm_mul_ps(
        _mm_mul_ps(_mm_set1_ps(3.0f), _mm_add_ps(_mm_add_ps(_mm_mul_ps(g3, _mm_mul_ps(maxE, maxZ)), _mm_mul_ps(deltaE, maxZ)),
                                                 _mm_mul_ps(deltaZ, maxE))),
        abs4(invDet));
    mask &= _mm_movemask_ps(_mm_cmpgt_ps(t, deltaT));
    _mm_storeu_ps(tOut, t);
    _mm_storeu_ps(b1Out, _mm_mul_ps(v, invDet));
    _mm_storeu_ps(b2Out, _mm_mul_ps(w, invDet));
  }
  for (int lanes = zeroLanes; lanes; lanes &= lanes - 1) {
    const int i = __builtin_ctz(static_cast<unsigned>(lanes));
    const Vec3 p0(tri.v[0][0][i], tri.v[0][1][i], tri.v[0][2][i]);
    const Vec3 p1(tri.v[1][0][i], tri.v[1][1][i], tri.v[1][2][i]);
    const Vec3 p2(tri.v[2][0][i], tri.v[2][1][i], tri.v[2][2][i]);
    if (intersectTriangleWatertight(ray.origin, rt.wr, p0, p1, p2, tMin, tMax, tOut[i], b1Out[i], b2Out[i]))
      mask |= 1 << i;
  }
  return mask;
}

/// Packet `tri` tested against the closest-hit query so far (tMax, hit): the nearest lane hit
/// in (tMin, tMax) becomes the closest. True when one did.
inline bool closerHit(const Triangle4& tri, const Ray& ray, const RayTri4& rt, float& tMax, Hit& hit) {
  float t[4], b1[4], b2[4];
  bool found = false;
  for (int mask = intersectTriangle4(tri, ray, rt, ray.tMin, tMax, t, b1, b2); mask; mask &= mask - 1) {
    const int i = __builtin_ctz(static_cast<unsigned>(mask));
    if (t[i] < tMax) {
      tMax = t[i];
      hit = {t[i], tri.id[i], b1[i], b2[i]};
      found = true;
    }
  }
  return found;
}

}  // namespace voxcone

#pragma once
// The watertight ray-triangle test (triangle.h) on packets of Triangle4s, shared by the HBVH's
// and the kd-tree's leaves: four triangles at once with SSE (F4), and with AVX2 (F8, where
// __AVX2__ is defined) two consecutive packets, eight triangles, at once. Both widths run one
// template, so every lane computes what the scalar-order SSE test computes. Compiled once per
// instruction set (hbvh_kernels.h), so it lives in a namespace named by VOXCONE_ISA (sse42
// unless the TU says otherwise) and reaches the scalar test only through an out-of-line call.

#include "voxcone/accel/accel.h"
#include "voxcone/accel/triangle.h"

#include <immintrin.h>

#include <cassert>
#include <cmath>
#include <cstdint>

#ifndef VOXCONE_ISA
#define VOXCONE_ISA sse42
#endif

namespace voxcone {

/// intersectTriangleWatertight on lane `lane` of the packet at `base` (hbvh_traverse.cpp,
/// compiled for the baseline instruction set, where it makes the ray's WatertightRay): the
/// packet test's rare exact-zero edge lanes. Packets are rows of floats: coordinate [vtx][axis]
/// of lane i at base[(3 vtx + axis) stride + i] (a Triangle4: stride 4; an HBVH leaf's packet
/// pair: stride 8).
bool intersectTriangleLane(const float* base, int stride, int lane, const Ray& ray, float tMin, float tMax,
                           float& tOut, float& b1Out, float& b2Out);

namespace VOXCONE_ISA {

/// Four floats (SSE). Comparisons give lane masks of the same type.
struct F4 {
  static constexpr int kLanes = 4;
  __m128 v;
  static F4 broadcast(float x) { return {_mm_set1_ps(x)}; }
  static F4 zero() { return {_mm_setzero_ps()}; }
  static F4 load(const float* row) { return {_mm_load_ps(row)}; }
  void store(float* out) const { _mm_storeu_ps(out, v); }
  int mask() const { return _mm_movemask_ps(v); }
};
inline F4 operator+(F4 a, F4 b) { return {_mm_add_ps(a.v, b.v)}; }
inline F4 operator-(F4 a, F4 b) { return {_mm_sub_ps(a.v, b.v)}; }
inline F4 operator*(F4 a, F4 b) { return {_mm_mul_ps(a.v, b.v)}; }
inline F4 operator/(F4 a, F4 b) { return {_mm_div_ps(a.v, b.v)}; }
inline F4 operator&(F4 a, F4 b) { return {_mm_and_ps(a.v, b.v)}; }
inline F4 operator|(F4 a, F4 b) { return {_mm_or_ps(a.v, b.v)}; }
inline F4 operator^(F4 a, F4 b) { return {_mm_xor_ps(a.v, b.v)}; }
inline F4 andNot(F4 a, F4 b) { return {_mm_andnot_ps(a.v, b.v)}; }  ///< ~a & b
inline F4 max(F4 a, F4 b) { return {_mm_max_ps(a.v, b.v)}; }
inline F4 operator==(F4 a, F4 b) { return {_mm_cmpeq_ps(a.v, b.v)}; }
inline F4 operator!=(F4 a, F4 b) { return {_mm_cmpneq_ps(a.v, b.v)}; }
inline F4 operator<(F4 a, F4 b) { return {_mm_cmplt_ps(a.v, b.v)}; }
inline F4 operator<=(F4 a, F4 b) { return {_mm_cmple_ps(a.v, b.v)}; }
inline F4 operator>(F4 a, F4 b) { return {_mm_cmpgt_ps(a.v, b.v)}; }
inline F4 operator>=(F4 a, F4 b) { return {_mm_cmpge_ps(a.v, b.v)}; }

#ifdef __AVX2__
/// Eight floats (AVX): a row of an HBVH leaf's packet pair in one load.
struct F8 {
  static constexpr int kLanes = 8;
  __m256 v;
  static F8 broadcast(float x) { return {_mm256_set1_ps(x)}; }
  static F8 zero() { return {_mm256_setzero_ps()}; }
  static F8 load(const float* row) { return {_mm256_load_ps(row)}; }
  void store(float* out) const { _mm256_storeu_ps(out, v); }
  int mask() const { return _mm256_movemask_ps(v); }
};
inline F8 operator+(F8 a, F8 b) { return {_mm256_add_ps(a.v, b.v)}; }
inline F8 operator-(F8 a, F8 b) { return {_mm256_sub_ps(a.v, b.v)}; }
inline F8 operator*(F8 a, F8 b) { return {_mm256_mul_ps(a.v, b.v)}; }
inline F8 operator/(F8 a, F8 b) { return {_mm256_div_ps(a.v, b.v)}; }
inline F8 operator&(F8 a, F8 b) { return {_mm256_and_ps(a.v, b.v)}; }
inline F8 operator|(F8 a, F8 b) { return {_mm256_or_ps(a.v, b.v)}; }
inline F8 operator^(F8 a, F8 b) { return {_mm256_xor_ps(a.v, b.v)}; }
inline F8 andNot(F8 a, F8 b) { return {_mm256_andnot_ps(a.v, b.v)}; }
inline F8 max(F8 a, F8 b) { return {_mm256_max_ps(a.v, b.v)}; }
inline F8 operator==(F8 a, F8 b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_EQ_OQ)}; }
inline F8 operator!=(F8 a, F8 b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_NEQ_UQ)}; }
inline F8 operator<(F8 a, F8 b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_LT_OQ)}; }
inline F8 operator<=(F8 a, F8 b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_LE_OQ)}; }
inline F8 operator>(F8 a, F8 b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_GT_OQ)}; }
inline F8 operator>=(F8 a, F8 b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_GE_OQ)}; }
#endif

/// WatertightRay's kx, ky by kz and the sign of dir[kz]: nibble 2 kz + negative is kx | ky << 2.
constexpr uint32_t packedNextAxes() {
  constexpr int kNext[3][2][2] = {{{1, 2}, {2, 1}}, {{2, 0}, {0, 2}}, {{0, 1}, {1, 0}}};
  uint32_t packed = 0;
  for (int z = 0; z < 3; ++z)
    for (int neg = 0; neg < 2; ++neg) packed |= uint32_t(kNext[z][neg][0] | kNext[z][neg][1] << 2) << (4 * (2 * z + neg));
  return packed;
}

/// Byte offsets of rows kx, ky, kz in a packet of 4 ([0]) or 8 ([1]) floats a row, for each
/// choice of kz and the sign of dir[kz] (index 2 kz + negative, as packedNextAxes).
struct PacketRowBytes {
  int64_t bytes[6][2][3];
  constexpr PacketRowBytes() : bytes() {
    for (int i = 0; i < 6; ++i) {
      const uint32_t next = packedNextAxes() >> (4 * i);
      const int k[3] = {int(next & 3u), int((next >> 2) & 3u), i / 2};
      for (int a = 0; a < 3; ++a) {
        bytes[i][0][a] = int64_t(k[a]) * 4 * int64_t(sizeof(float));
        bytes[i][1][a] = int64_t(k[a]) * 8 * int64_t(sizeof(float));
      }
    }
  }
};
inline constexpr PacketRowBytes kPacketRowBytes;

/// Per-ray constants of the packet test: WatertightRay's permutation and shear (the same values;
/// made here rather than by WatertightRay's inline constructor, which a kernel TU would compile
/// for its own instruction set and the linker might keep for all). Without a branch: the axis
/// choice follows the ray's direction, which a branch predictor cannot guess for incoherent rays.
struct RayTri4 {
  int kx, ky, kz;
  int axes;  ///< 2 kz + (dir[kz] < 0): the index of kPacketRowBytes
  float sx, sy, sz;
  float dz;  ///< |d[kz]|, as WatertightRay's
  float org[3];
  explicit RayTri4(const Ray& r) : org{r.origin.x, r.origin.y, r.origin.z} {
    const float d[3] = {r.dir.x, r.dir.y, r.dir.z};
    const float ax = std::fabs(d[0]), ay = std::fabs(d[1]), az = std::fabs(d[2]);
    // maxDimension: ax > ay ? (ax > az ? 0 : 2) : (ay > az ? 1 : 2), as flags.
    const int xy = ax > ay, xz = ax > az, yz = ay > az;
    kz = 2 - 2 * (xy & xz) - ((xy ^ 1) & yz);
    // kx, ky follow kz cyclically, swapped where dir[kz] < 0 (winding).
    const int neg = d[kz] < 0.0f;
    axes = 2 * kz + neg;
    const uint32_t next = packedNextAxes() >> (4 * axes);
    kx = int(next & 3u);
    ky = int((next >> 2) & 3u);
    sz = 1.0f / d[kz];
    sx = d[kx] * sz;
    sy = d[ky] * sz;
    dz = std::fabs(d[kz]);
  }
};

/// RayTri4 spread over eight lanes, with the byte offsets of the rows its axes select: what the
/// packet test reads of a ray, made once a ray (the HBVH: at its first leaf), so that a leaf test
/// loads it rather than broadcasting eight values and scaling three axes (GCC broadcast them once
/// a leaf and spilled them to the stack).
struct alignas(32) RayTriLanes {
  enum Row { kOrgX, kOrgY, kOrgZ, kSx, kSy, kSz, kTMin, kDz, kRows };
  float lanes[kRows][8];  ///< origin[kx], origin[ky], origin[kz], sx, sy, sz, tMin, |d[kz]|
  /// Byte offsets of rows kx, ky, kz in a packet of 4 ([0]) or 8 ([1]) floats a row (a row of
  /// kPacketRowBytes: a table rather than six products a ray).
  const int64_t (*rowBytes)[3];
  explicit RayTriLanes(const Ray& r) {
    const RayTri4 rt(r);
    const int k[3] = {rt.kx, rt.ky, rt.kz};
    const float v[kRows] = {rt.org[k[0]], rt.org[k[1]], rt.org[k[2]], rt.sx, rt.sy, rt.sz, r.tMin, rt.dz};
    for (int i = 0; i < kRows; ++i)
      for (int l = 0; l < 8; ++l) lanes[i][l] = v[i];
    rowBytes = kPacketRowBytes.bytes[rt.axes];
  }
  template <class F>
  F get(Row row) const { return F::load(lanes[row]); }
};

/// The watertight test (triangle.h) on F::kLanes triangles at once (the rows of `base`,
/// `stride` floats apart; F8 needs stride 8), with the same operations in the same order as the
/// scalar test, so both give the same t and the same answer. Lanes where an edge function is
/// exactly zero are redone by the scalar test, which resolves them in double precision. Returns
/// the mask of lanes hit in (tMin, tMax) and their t and barycentrics; with kDeferEdges, -1
/// (kEdgeLanes) instead where any lane needs the scalar test, so that a caller may keep that call
/// out of its loop.
constexpr int kEdgeLanes = -1;
template <class F, bool kDeferEdges = false>
inline int intersectPackets(const float* base, int stride, const Ray& ray, const RayTriLanes& rl, float tMax,
                            float* tOut, float* b1Out, float* b2Out) {
  using R = RayTriLanes;
  assert(stride == 4 || stride == 8);
  const int64_t* rowBytes = rl.rowBytes[stride == 8];  // known where inlined
  const F sx = rl.get<F>(R::kSx), sy = rl.get<F>(R::kSy), sz = rl.get<F>(R::kSz);
  F px[3], py[3], pz[3];  // per vertex: sheared x, y and the unsheared z coordinate
  for (int vtx = 0; vtx < 3; ++vtx) {
    const char* rows = reinterpret_cast<const char*>(base + 3 * vtx * stride);
    const auto row = [&](int a) { return F::load(reinterpret_cast<const float*>(rows + rowBytes[a])); };
    const F x = row(0) - rl.get<F>(R::kOrgX);
    const F y = row(1) - rl.get<F>(R::kOrgY);
    pz[vtx] = row(2) - rl.get<F>(R::kOrgZ);
    px[vtx] = x - sx * pz[vtx];
    py[vtx] = y - sy * pz[vtx];
  }
  // Scaled barycentrics: 2D edge functions (A = vertex 0, B = 1, C = 2).
  const F u = px[2] * py[1] - py[2] * px[1];
  const F v = px[0] * py[2] - py[0] * px[2];
  const F w = px[1] * py[0] - py[1] * px[0];
  const F zero = F::zero();
  const int zeroLanes = ((u == zero) | (v == zero) | (w == zero)).mask();
  if constexpr (kDeferEdges) {
    if (__builtin_expect(zeroLanes != 0, 0)) return kEdgeLanes;
  }
  // Inside when all three share a sign: their sign bits agree, so (u ^ v) | (u ^ w) has a clear
  // sign bit. Exact zeros, whose sign says nothing, are the scalar test's (zeroLanes, below);
  // NaN lanes (padding) fail the ordered distance comparisons.
  const F det = u + v + w;
  const F mixedSigns = (u ^ v) | (u ^ w);
  F valid = andNot(mixedSigns, det != zero);  // det != zero is all ones or zero: its sign bit
  // Scaled distance compared against the range before dividing; |det| and the sign-flipped
  // distance replace the scalar test's two branches.
  const F tScaled = u * (sz * pz[0]) + v * (sz * pz[1]) + w * (sz * pz[2]);
  const F signMask = F::broadcast(-0.0f);
  const F detSign = det & signMask;
  const F detAbs = det ^ detSign;
  const F tAbs = tScaled ^ detSign;
  valid = valid & (tAbs > rl.get<F>(R::kTMin) * detAbs) & (tAbs <= F::broadcast(tMax * kTMaxPrefilter) * detAbs);
  int mask = valid.mask() & ~zeroLanes;
  if (mask) {
    const F invDet = F::broadcast(1.0f) / det;
    const F t = tScaled * invDet;
    mask &= (t < F::broadcast(tMax)).mask();  // as the scalar test: the divided distance decides
    // Only distances above their own rounding error (watertightDistanceError, lane by lane).
    const auto abs = [&](F a) { return andNot(signMask, a); };
    const auto max3 = [&](F a, F b, F c) { return max(abs(a), max(abs(b), abs(c))); };
    const F maxZ = max3(pz[0], pz[1], pz[2]);
    const F maxX = max3(px[0], px[1], px[2]);
    const F maxY = max3(py[0], py[1], py[2]);
    const F maxE = max3(u, v, w);
    const F g2 = F::broadcast(errorGamma(2)), g3 = F::broadcast(errorGamma(3)), g5 = F::broadcast(errorGamma(5));
    const F deltaZ = g3 * maxZ;
    const F deltaX = g5 * (maxX + maxZ);
    const F deltaY = g5 * (maxY + maxZ);
    const F deltaE = F::broadcast(2.0f) * (g2 * (maxX * maxY) + deltaY * maxX + deltaX * maxY);
    const F deltaT = F::broadcast(3.0f) * (g3 * (maxE * maxZ) + deltaE * maxZ + deltaZ * maxE) * abs(invDet);
    mask &= (t * rl.get<F>(R::kDz) > deltaT).mask();
    t.store(tOut);
    (v * invDet).store(b1Out);
    (w * invDet).store(b2Out);
  }
  for (int lanes = zeroLanes; lanes; lanes &= lanes - 1) {
    const int i = __builtin_ctz(static_cast<unsigned>(lanes));
    if (intersectTriangleLane(base, stride, i, ray, ray.tMin, tMax, tOut[i], b1Out[i], b2Out[i]))
      mask |= 1 << i;
  }
  return mask;
}

/// One packet, four lanes (the kd-tree's test).
inline int intersectTriangle4(const Triangle4& tri, const Ray& ray, const RayTriLanes& rl, float tMax, float tOut[4],
                              float b1Out[4], float b2Out[4]) {
  return intersectPackets<F4>(tri.v[0][0], 4, ray, rl, tMax, tOut, b1Out, b2Out);
}

/// Packets [first, first + count) against the closest-hit query so far (tMax, hit), one at a
/// time, lanes in order (the nearest, the first of equals, becomes the closest): the kd-tree's
/// leaves. True when one was closer.
inline bool closerHits(const Triangle4* first, uint32_t count, const Ray& ray, const RayTriLanes& rl, float& tMax,
                       Hit& hit) {
  bool found = false;
  for (uint32_t p = 0; p < count; ++p) {
    alignas(16) float t[4], b1[4], b2[4];
    for (int mask = intersectTriangle4(first[p], ray, rl, tMax, t, b1, b2); mask; mask &= mask - 1) {
      const int i = __builtin_ctz(static_cast<unsigned>(mask));
      if (t[i] < tMax) {
        tMax = t[i];
        hit = {t[i], first[p].id[i], b1[i], b2[i]};
        found = true;
      }
    }
  }
  return found;
}

/// Any hit among packets [first, first + count) in (tMin, tMax).
inline bool anyHit(const Triangle4* first, uint32_t count, const Ray& ray, const RayTriLanes& rl, float tMax) {
  alignas(16) float t[4], b1[4], b2[4];
  for (uint32_t p = 0; p < count; ++p)
    if (intersectTriangle4(first[p], ray, rl, tMax, t, b1, b2)) return true;
  return false;
}

}  // namespace VOXCONE_ISA
}  // namespace voxcone

#pragma once
// The HBVH kernels' box and sphere tests (hbvh_traverse_kernel.h): the SIMD lanes of one node's
// children (one AVX register per plane where __AVX2__ is defined, two SSE halves where not), the
// padded and robust slab tests and their per-ray constants, and the sphere test's. Compiled once
// per instruction set as part of hbvh_traverse_kernel.h, in namespace voxcone::VOXCONE_ISA.

#ifndef VOXCONE_ISA
#error "define VOXCONE_ISA (sse42, avx2 or avx512) before including hbvh_box_tests.h"
#endif

#include "hbvh_kernels.h"

#include <immintrin.h>

#include <cstddef>
#include <cstdint>
#include <cstring>

namespace voxcone {
namespace VOXCONE_ISA {

namespace {

using Node = Hbvh::Node;
using QNode = Hbvh::QNode;
constexpr int kWidth = Hbvh::kWidth;
constexpr uint32_t kLeafBit = Hbvh::kLeafBit, kCountShift = Hbvh::kCountShift, kSlotMask = Hbvh::kSlotMask;
constexpr uint32_t kQuantBit = Hbvh::kQuantBit;

/// 1 + 2 gamma(3) (Ize 2013, sec. 3.3).
constexpr float kSlabScale = 1.0f + 2.0f * (3.0f * 0x1p-24f) / (1.0f - 3.0f * 0x1p-24f);

#ifdef __AVX2__
using VFloat = __m256;  ///< one plane of all eight children
inline VFloat broadcast(float x) { return _mm256_set1_ps(x); }
inline VFloat load(const float* p) { return _mm256_load_ps(p); }
inline void store(float* p, VFloat a) { _mm256_store_ps(p, a); }
inline VFloat sub(VFloat a, VFloat b) { return _mm256_sub_ps(a, b); }
inline VFloat mul(VFloat a, VFloat b) { return _mm256_mul_ps(a, b); }
/// a b + c: rounded once (FMA) here, twice in the SSE kernels (the same float where a b is exact).
inline VFloat mulAdd(VFloat a, VFloat b, VFloat c) { return _mm256_fmadd_ps(a, b, c); }
/// Eight bytes from p as floats.
inline VFloat loadBytes(const uint8_t* p) {
  return _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(p))));
}
inline VFloat imin(VFloat a, VFloat b) {
  return _mm256_castsi256_ps(_mm256_min_epi32(_mm256_castps_si256(a), _mm256_castps_si256(b)));
}
inline VFloat imax(VFloat a, VFloat b) {
  return _mm256_castsi256_ps(_mm256_max_epi32(_mm256_castps_si256(a), _mm256_castps_si256(b)));
}
/// Lanes where a <= b, ordered as integers.
inline int lessEqualMask(VFloat a, VFloat b) {
#ifdef __AVX512VL__
  return _mm256_cmple_epi32_mask(_mm256_castps_si256(a), _mm256_castps_si256(b));  // into a mask register
#else
  return 0xff ^ _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpgt_epi32(_mm256_castps_si256(a), _mm256_castps_si256(b))));
#endif
}
#else
using VFloat = __m128;  ///< one plane of four children (a node takes two)
inline VFloat broadcast(float x) { return _mm_set1_ps(x); }
inline VFloat load(const float* p) { return _mm_load_ps(p); }
inline void store(float* p, VFloat a) { _mm_store_ps(p, a); }
inline VFloat sub(VFloat a, VFloat b) { return _mm_sub_ps(a, b); }
inline VFloat mul(VFloat a, VFloat b) { return _mm_mul_ps(a, b); }
inline VFloat mulAdd(VFloat a, VFloat b, VFloat c) { return _mm_add_ps(_mm_mul_ps(a, b), c); }
/// Four bytes from p as floats.
inline VFloat loadBytes(const uint8_t* p) {
  int32_t bytes;
  std::memcpy(&bytes, p, sizeof bytes);
  return _mm_cvtepi32_ps(_mm_cvtepu8_epi32(_mm_cvtsi32_si128(bytes)));
}
inline VFloat imin(VFloat a, VFloat b) { return _mm_castsi128_ps(_mm_min_epi32(_mm_castps_si128(a), _mm_castps_si128(b))); }
inline VFloat imax(VFloat a, VFloat b) { return _mm_castsi128_ps(_mm_max_epi32(_mm_castps_si128(a), _mm_castps_si128(b))); }
inline int lessEqualMask(VFloat a, VFloat b) {
  return 0xf ^ _mm_movemask_ps(_mm_castsi128_ps(_mm_cmpgt_epi32(_mm_castps_si128(a), _mm_castps_si128(b))));
}
#endif

/// Byte offsets in a Node (and, a quarter of them, in a QNode) of the entry (near) and exit
/// (far) planes on each axis, for each combination of the direction's signs (bit a: dir[a] < 0
/// swaps lo and hi).
struct BoxPlaneOffsets {
  struct Row {
    int64_t near[3], far[3];
    int64_t nearQ[3], farQ[3];  ///< a QNode's, a quarter of those (enterBoxesQ)
  };
  Row rows[8];
  constexpr BoxPlaneOffsets() : rows() {
    for (int negative = 0; negative < 8; ++negative)
      for (int a = 0; a < 3; ++a) {
        const int64_t lo = offsetof(Node, lo) + a * sizeof(float[kWidth]);
        const int64_t hi = offsetof(Node, hi) + a * sizeof(float[kWidth]);
        const bool swap = (negative >> a) & 1;
        rows[negative].near[a] = swap ? hi : lo;
        rows[negative].far[a] = swap ? lo : hi;
        rows[negative].nearQ[a] = rows[negative].near[a] / 4;
        rows[negative].farQ[a] = rows[negative].far[a] / 4;
      }
  }
};
inline constexpr BoxPlaneOffsets kBoxPlaneOffsets;

/// The box test's reciprocal direction: a zero component becomes a tiny one of its sign, so that
/// 0 * inf never makes a NaN distance; the three in one division, each correctly rounded (as
/// three scalar ones).
inline __m128 boxReciprocal(const Ray& r) {
  const __m128 d = _mm_setr_ps(r.dir.x, r.dir.y, r.dir.z, 1.0f);
  const __m128 signBit = _mm_set1_ps(-0.0f);
  const __m128 tiny = _mm_or_ps(_mm_and_ps(d, signBit), _mm_set1_ps(1e-30f));
  const __m128 small = _mm_cmplt_ps(_mm_andnot_ps(signBit, d), _mm_set1_ps(1e-30f));
  const __m128 safe = _mm_or_ps(_mm_and_ps(small, tiny), _mm_andnot_ps(small, d));
  return _mm_div_ps(_mm_set1_ps(1.0f), safe);
}

/// The byte offsets in a Node (and a QNode) of the entry and exit planes on each axis (lo or hi
/// by the sign of the direction), so that the box test has no branch: kBoxPlaneOffsets' row for
/// the ray, read through a pointer. Copied into the ray (as they were), GCC kept all twelve on
/// the stack anyway, and making them was about 40 of a ray's instructions (callgrind, dragon
/// primary rays, AVX2: 909 -> 869 a ray through the pointer, 932 copying the row's twelve).
/// Measured (bench/hbvh_vs_embree, dragon, 7 alternating runs, medians of two sets of 3 and 4,
/// copied / pointer): primary 1.005 / 1.055 and 1.098 / 1.130, incoherent 1.150 / 1.132 and
/// 1.170 / 1.142 (a node's offsets now a load further from its planes), secondary 1.102 / 1.079
/// and 1.12 / 1.12, shadow 1.099 / 1.116 and 1.099 / 1.116; 10M knot incoherent (2 runs) 1.059-
/// 1.068 / 1.056-1.060. The primary rays, in cache, had the thinnest margin.
struct BoxPlanes {
  const BoxPlaneOffsets::Row* planes;
  explicit BoxPlanes(const Ray& r) {
    // The sign bits of the direction (those of boxReciprocal's, which keeps a zero's sign).
    const int negative = _mm_movemask_ps(_mm_setr_ps(r.dir.x, r.dir.y, r.dir.z, 0.0f));
    planes = &kBoxPlaneOffsets.rows[negative];
  }
};

/// The robust box test's per-ray constants: a slab distance is (p - o) (1/d), rounded twice,
/// and the exit distances are widened by kSlabScale (Ize 2013), which makes the test
/// conservative for any ray and any box.
struct RobustBoxRay : BoxPlanes {
  VFloat org[3], invDir[3];
  /// invDir times kSlabScale, for the exit distances: (hi - o) (1/d S) rounds four times, as
  /// ((hi - o) 1/d) S did, so the widening bounds the same error, with one product less a node.
  VFloat invDirFar[3];
  explicit RobustBoxRay(const Ray& r) : BoxPlanes(r) {
    const __m128 invV = boxReciprocal(r);
    alignas(16) float inv[4], invFar[4];
    _mm_store_ps(inv, invV);
    _mm_store_ps(invFar, _mm_mul_ps(invV, _mm_set1_ps(kSlabScale)));
    for (int a = 0; a < 3; ++a) {
      org[a] = broadcast(r.origin[a]);
      invDir[a] = broadcast(inv[a]);
      invDirFar[a] = broadcast(invFar[a]);
    }
  }
  VFloat nearT(VFloat plane, int a) const { return mul(sub(plane, org[a]), invDir[a]); }
  VFloat farT(VFloat plane, int a) const { return mul(sub(plane, org[a]), invDirFar[a]); }
  /// A QNode's planes on axis a: dequantized (origin + q scale, in float, as the build checked
  /// it), then the same distances.
  struct QAxis {
    VFloat scale, origin;
  };
  QAxis qAxis(const QNode& n, int a) const { return {broadcast(n.scale[a]), broadcast(n.origin[a])}; }
  VFloat nearQ(VFloat q, const QAxis& x, int a) const { return nearT(plane(q, x), a); }
  VFloat farQ(VFloat q, const QAxis& x, int a) const { return farT(plane(q, x), a); }
  /// q scale is exact (a power of two), so every kernel rounds this once, as the build did.
  static VFloat plane(VFloat q, const QAxis& x) { return mulAdd(q, x.scale, x.origin); }
};

/// The padded box test's per-ray constants: a slab distance is p (1/d) + K with K = -o (1/d),
/// one FMA (Embree's form; a product and a sum in the SSE kernels), with no widening. Its
/// rounding error is an absolute one, which the boxes' padding covers for the rays
/// paddedBoxesHold admits (hbvh_build.cpp, paddedOriginBound, derives the bound).
struct PaddedBoxRay : BoxPlanes {
  VFloat invDir[3], orgInv[3];  ///< 1/d and K
  explicit PaddedBoxRay(const Ray& r) : BoxPlanes(r) {
    const __m128 invV = boxReciprocal(r);
    alignas(16) float inv[4], k[4];
    _mm_store_ps(inv, invV);
    const __m128 o = _mm_setr_ps(r.origin.x, r.origin.y, r.origin.z, 0.0f);
    _mm_store_ps(k, _mm_xor_ps(_mm_mul_ps(o, invV), _mm_set1_ps(-0.0f)));  // -(o (1/d)), rounded once
    for (int a = 0; a < 3; ++a) {
      invDir[a] = broadcast(inv[a]);
      orgInv[a] = broadcast(k[a]);
    }
  }
  VFloat nearT(VFloat plane, int a) const { return mulAdd(plane, invDir[a], orgInv[a]); }
  VFloat farT(VFloat plane, int a) const { return nearT(plane, a); }  // no widening
  /// A QNode's planes on axis a: (origin + q scale) (1/d) + K = q (scale (1/d)) + (origin (1/d)
  /// + K), with scale (1/d) exact (scale is a power of two), so a plane costs one FMA, as a
  /// full node's.
  struct QAxis {
    VFloat scaleInv, offset;
  };
  QAxis qAxis(const QNode& n, int a) const {
    return {mul(broadcast(n.scale[a]), invDir[a]), mulAdd(broadcast(n.origin[a]), invDir[a], orgInv[a])};
  }
  VFloat nearQ(VFloat q, const QAxis& x, int) const { return mulAdd(q, x.scaleInv, x.offset); }
  VFloat farQ(VFloat q, const QAxis& x, int a) const { return nearQ(q, x, a); }
};

/// Whether the padded test is conservative for this ray in this tree (hbvh_build.cpp,
/// paddedOriginBound, derives the bound): every origin component within it in magnitude, every
/// direction component at most 2^64 (so that 1/d is a normal float) and the largest at least
/// 2^-40. NaN fails.
inline bool paddedBoxesHold(const HbvhArrays& bvh, const Ray& r) {
  static_assert(offsetof(Ray, dir) == 3 * sizeof(float) && offsetof(Ray, tMin) == 6 * sizeof(float),
                "origin, dir and tMin lie in a row");
  const __m128 magnitude = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
  const __m128 od = _mm_and_ps(_mm_loadu_ps(&r.origin.x), magnitude);  // |o|, |d.x|
  const __m128 dt = _mm_and_ps(_mm_loadu_ps(&r.dir.x), magnitude);     // |d|, |tMin|
  const float bound = bvh.paddedOriginBound;
  const __m128 ok = _mm_and_ps(_mm_cmple_ps(od, _mm_setr_ps(bound, bound, bound, 0x1p64f)),
                               _mm_cmple_ps(dt, _mm_setr_ps(0x1p64f, 0x1p64f, 0x1p64f, INFINITY)));
  return _mm_movemask_ps(ok) == 0xf && (_mm_movemask_ps(_mm_cmpge_ps(dt, _mm_set1_ps(0x1p-40f))) & 7) != 0;
}

/// The sphere test's per-ray constants (a square root and a division), made on the first sphere
/// a ray meets: few children keep one (74 of the dragon's 161k).
struct SphereRay {
  Vec3 dirUnit{0.0f};
  float invLen = 0.0f;  ///< 0 until made
  void make(const Ray& r) {
    invLen = 1.0f / glm::length(r.dir);
    dirUnit = r.dir * invLen;
  }
};

/// The slab test of one register's width of children: their entry distances into tNearOut and
/// the mask of those entered, from bit 0; nearT(a) and farT(a) give the entry and exit distances
/// of the children's planes on axis a.
/// Distances are ordered as 32-bit integers (one cycle a minimum, against four for floats; as
/// Embree's kernels do), which orders floats of which one at least is not negative: the entry
/// distance is the largest of the planes' and tMin >= 0 (Hbvh::intersect clamps it), so it is
/// the float maximum; an exit distance is the float minimum where all are >= 0, and a negative
/// one where any is, which no entry distance is at or below (a box left at t = -0, where -0
/// orders below +0, holds nothing in the open interval (tMin, tMax)).
template <class NearT, class FarT>
[[gnu::always_inline]] inline int slabTest(NearT nearT, FarT farT, VFloat tMin, VFloat tMax, float* tNearOut) {
  const VFloat tNear = imax(imax(tMin, nearT(0)), imax(nearT(1), nearT(2)));
  const VFloat tFar = imin(imin(farT(0), farT(1)), imin(farT(2), tMax));
  store(tNearOut, tNear);
  return lessEqualMask(tNear, tFar);
}

/// The slab test of a Node's children from `first` on (tNearOut[first..]).
template <class BoxRay>
inline int enterBoxes(const Node& n, int first, const BoxRay& rd, VFloat tMin, VFloat tMax, float* tNearOut) {
  const char* base = reinterpret_cast<const char*>(&n) + first * sizeof(float);
  const auto plane = [&](int64_t offset) { return load(reinterpret_cast<const float*>(base + offset)); };
  return slabTest([&](int a) { return rd.nearT(plane(rd.planes->near[a]), a); },
                  [&](int a) { return rd.farT(plane(rd.planes->far[a]), a); }, tMin, tMax, tNearOut + first);
}

/// enterBoxes for a QNode. A plane's bytes lie at a quarter of its floats' offset in a Node
/// (lo[a] at 32 a bytes there, 8 a here; hi at 96 + 32 a, 24 + 8 a), from lo on.
template <class BoxRay>
inline int enterBoxesQ(const QNode& n, int first, const BoxRay& rd, VFloat tMin, VFloat tMax, float* tNearOut) {
  const uint8_t* base = &n.lo[0][0] + first;
  const typename BoxRay::QAxis axis[3] = {rd.qAxis(n, 0), rd.qAxis(n, 1), rd.qAxis(n, 2)};
  return slabTest([&](int a) { return rd.nearQ(loadBytes(base + rd.planes->nearQ[a]), axis[a], a); },
                  [&](int a) { return rd.farQ(loadBytes(base + rd.planes->farQ[a]), axis[a], a); }, tMin, tMax,
                  tNearOut + first);
}
static_assert(offsetof(Node, lo) == 0 && offsetof(Node, hi) == 4 * (offsetof(QNode, hi) - offsetof(QNode, lo)),
              "a QNode's planes lie at a quarter of a Node's offsets");

}  // namespace
}  // namespace VOXCONE_ISA
}  // namespace voxcone

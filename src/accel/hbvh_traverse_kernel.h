// HBVH traversal over 8-wide nodes, compiled once per instruction set (hbvh_kernels.h): the
// eight child boxes of a node are tested at once, in one AVX register per plane where __AVX2__
// is defined and in two SSE halves where not. The AVX-512 kernels are the AVX2 ones (256-bit
// registers) with AVX-512VL where it saves instructions: box compares into mask registers, and
// vpcompressd to push the entered children.
// Two box tests: for rays whose origin lies within the bound the build padded the boxes for
// (paddedBoxesHold), Embree's slab distance p (1/d) - o (1/d), one FMA (a product and a sum in
// SSE), whose rounding the padding covers (PaddedBoxRay; hbvh_build.cpp, paddedOriginBound);
// for others the robust slab test (Ize 2013, "Robust BVH Ray Traversal", JCGT 2(2): the exit
// distance widened by 1 + 2 gamma(3); RobustBoxRay). Both are conservative, so every kernel
// visits the leaves that hold the hits, and of hits at the same distance the smaller triangle id
// wins (closerHitsLeaf): every kernel finds the same hit, bit for bit, as brute force does,
// whatever order its box distances give (the triangle test runs the same operations in every
// kernel, -ffp-contract=off; tested: Hbvh.PaddedAndRobustBoxTestsFindTheBruteForceHits).
// A child that keeps a bounding sphere must also be entered by the ray's sphere interval.
// Closest-hit traversal visits the hit children nearest first; shadow rays go on with the
// farthest below a full node (occludedWith says why).
// Everything here lives in namespace voxcone::VOXCONE_ISA, so that the compilations never
// share an inline function (the linker would keep one of them for all).

#ifndef VOXCONE_ISA
#error "define VOXCONE_ISA (sse42, avx2 or avx512) before including hbvh_traverse_kernel.h"
#endif

#include "hbvh_kernels.h"
#include "triangle4_sse.h"

#include <immintrin.h>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <new>
#include <type_traits>

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

/// Children in `mask` that keep a sphere and whose sphere the ray misses (in [tMin, tMax]) are
/// removed from it; tNear of the others becomes the later of the box's and the sphere's entry.
/// Out of line: few nodes have spheres, and inlined it would crowd the box test's registers.
template <class NodeT>
[[gnu::noinline]] int cullSpheres(const NodeT& n, const Vec4* spheres, const Ray& ray, SphereRay& sr, int mask,
                                  float tMin, float tMax, float* tNear) {
  // Distance of closest approach along the unit direction (Haines et al., "Precision
  // Improvements for Ray/Sphere Intersection", Ray Tracing Gems ch. 7).
  if (sr.invLen == 0.0f) sr.make(ray);
  uint32_t sphereIdx = n.sphereBase;
  for (int i = 0; i < kWidth; ++i) {
    if (!(n.sphereMask & (1u << i))) continue;
    const Vec4& s = spheres[sphereIdx++];
    if (!(mask & (1 << i))) continue;
    const Vec3 f = ray.origin - Vec3(s);
    const float b = -glm::dot(f, sr.dirUnit);
    const Vec3 l = f + b * sr.dirUnit;
    // Rounding in l grows with |f|, not with the radius: widen the radius by 1e-6 |f|.
    const float rEff = s.w + 1e-6f * std::sqrt(glm::dot(f, f));
    const float disc = rEff * rEff - glm::dot(l, l);
    bool hit = disc >= 0.0f;
    if (hit) {
      const float h = std::sqrt(disc);
      const float sNear = (b - h) * sr.invLen, sFar = (b + h) * sr.invLen;
      tNear[i] = tNear[i] < sNear ? sNear : tNear[i];  // std::max
      hit = tNear[i] <= (tMax < sFar ? tMax : sFar) && sFar >= tMin;  // std::min, inline here
    }
    if (!hit) mask &= ~(1 << i);
  }
  return mask;
}

/// Entry distances of the eight children and the mask of those entered.
template <bool kSpheres, class NodeT, class BoxRay>
inline int enterChildren(const NodeT& n, const Vec4* spheres, const Ray& ray, const BoxRay& rd, SphereRay& sr,
                         float tMin, float tMax, float tNearOut[kWidth]) {
  const VFloat tMinV = broadcast(tMin), tMaxV = broadcast(tMax);
  const auto boxes = [&](int first) {
    if constexpr (std::is_same_v<NodeT, QNode>) return enterBoxesQ(n, first, rd, tMinV, tMaxV, tNearOut);
    else return enterBoxes(n, first, rd, tMinV, tMaxV, tNearOut);
  };
#ifdef __AVX2__
  int mask = boxes(0);
#else
  int mask = boxes(0) | boxes(4) << 4;
#endif
  if constexpr (std::is_same_v<NodeT, QNode>) mask &= int(n.used);
  if constexpr (kSpheres) {
    if (__builtin_expect((mask & n.sphereMask) != 0, 0))
      mask = cullSpheres(n, spheres, ray, sr, mask, tMin, tMax, tNearOut);
  }
  return mask;
}

/// Lines after a QNode that prefetchAfterQNode starts loading.
constexpr int kLinesAfterQNode = 14;

/// Start loading the kLinesAfterQNode lines that follow QNode n, its leaves (Hbvh::BlockLine
/// says why they follow it) and what follows them, as its own lines are loaded: otherwise the
/// leaves' loads waited for the QNode's test, one memory latency after it. perf (dragon,
/// incoherent rays) had 20% of the kernel's samples on a leaf's first row and 18% on a QNode's
/// first line. Measured (bench/hbvh_vs_embree, one thread, ratio to Embree MEDIUM, medians of
/// 3 alternating runs, 0 / 8 / 14 / 24 lines): dragon primary 1.051 / 1.117 / 1.068 / 1.065,
/// incoherent 1.006 / 1.119 / 1.153 / 1.118, secondary 1.018 / 1.115 / 1.094 / 1.073, shadow
/// 1.027 / 1.100 / 1.116 / 1.076; 10M knot (2 runs, 0 / 8 / 14) primary 1.06 / 1.27 / 1.29,
/// incoherent 0.98 / 1.07 / 1.07, secondary 1.04 / 1.25 / 1.22, shadow 1.05 / 1.21 / 1.24.
/// Exactly the QNode's own leaves (a line count in its reference, up to 14 or 28 lines)
/// measured no better than a fixed count. A prefetch past the array's end does not fault.
[[gnu::always_inline]] inline void prefetchAfterQNode(const QNode& n) {
  const char* p = reinterpret_cast<const char*>(&n + 1);
  for (int l = 0; l < kLinesAfterQNode; ++l) _mm_prefetch(p + 64 * l, _MM_HINT_T0);
}

/// enterChildren for the node `ref` refers to (a QNode where kQuantBit is set); `child` gets the
/// node's child references.
template <bool kSpheres, class BoxRay>
[[gnu::always_inline]] inline int enterNode(const HbvhArrays& bvh, uint32_t ref, const Ray& ray, const BoxRay& rd,
                                            SphereRay& sr, float tMin, float tMax, float tNearOut[kWidth],
                                            const uint32_t*& child) {
  if (ref & kQuantBit) {
    const QNode& n = bvh.qnode(ref);
    prefetchAfterQNode(n);
    child = n.child;
    return enterChildren<kSpheres>(n, bvh.spheres, ray, rd, sr, tMin, tMax, tNearOut);
  }
  const Node& n = bvh.node(ref);
  child = n.child;
  return enterChildren<kSpheres>(n, bvh.spheres, ray, rd, sr, tMin, tMax, tNearOut);
}

/// The packet test's constants, made at a ray's first leaf: most primary rays (62% miss the
/// dragon) never reach one.
struct LeafRay {
  // Raw storage: a default-constructed RayTriLanes member made GCC warn (maybe-uninitialized)
  // wherever a leaf test reads it behind the flag, and std::optional<RayTriLanes> costs
  // instructions (callgrind, bunny: primary 736 -> 797 M a pass, occlusion 589 -> 617 M).
  alignas(RayTriLanes) unsigned char storage[sizeof(RayTriLanes)];
  bool made = false;
  const RayTriLanes& get(const Ray& ray) {
    if (!made) {
      new (storage) RayTriLanes(ray);
      made = true;
    }
    return *std::launder(reinterpret_cast<const RayTriLanes*>(storage));
  }
};

/// A leaf reference's first LeafUnit and packet count.
inline uint32_t leafFirst(uint32_t ref) { return ref & kSlotMask; }
inline uint32_t leafPackets(uint32_t ref) { return ((ref & ~kLeafBit) >> kCountShift) + 1u; }

/// Start loading what `c` refers to: a node's lines (four, a QNode's two), or a leaf's first
/// four. Always inlined (prefetchChildren, below, says why).
[[gnu::always_inline]] inline void prefetchRef(const HbvhArrays& bvh, uint32_t c) {
  const bool leaf = c & kLeafBit;
  const char* p = leaf               ? reinterpret_cast<const char*>(bvh.leaf(leafFirst(c)))
                   : (c & kQuantBit) ? reinterpret_cast<const char*>(&bvh.qnode(c))
                                     : reinterpret_cast<const char*>(&bvh.node(c));
  _mm_prefetch(p, _MM_HINT_T0);
  _mm_prefetch(p + 64, _MM_HINT_T0);
  if (leaf || !(c & kQuantBit)) {
    _mm_prefetch(p + 128, _MM_HINT_T0);
    _mm_prefetch(p + 192, _MM_HINT_T0);
  }
}

/// Start loading the entered children while their order is worked out: on the dragon a third
/// of the kernel's samples wait on those loads. A node's four lines; a leaf's first two packets
/// (of at most two), which start 32 bytes into a line as often as not and then span six lines.
/// Every line the test reads pays: prefetching every other line only (for the L2's pair
/// prefetcher to complete) made incoherent rays 0.92 -> 0.84x Embree's; the sixth line of a leaf
/// 0.92 -> 0.93, and prefetching no more than a one-packet leaf's three lines no better than that.
/// Always inlined: out of line, GCC 12 finds this function "looping pure" (it takes
/// __builtin_prefetch for side-effect free) and deletes every call, and with them the prefetches
/// (the binary had not one prefetcht0 until this attribute; dragon incoherent 0.82 -> 0.92).
[[gnu::always_inline]] inline void prefetchChildren(const HbvhArrays& bvh, const uint32_t* child, int mask) {
  for (; mask; mask &= mask - 1) {
    const uint32_t c = child[__builtin_ctz(static_cast<unsigned>(mask))];
    prefetchRef(bvh, c);
    if (c & kLeafBit) {
      const char* p = reinterpret_cast<const char*>(bvh.leaf(leafFirst(c)));
      _mm_prefetch(p + 256, _MM_HINT_T0);
      _mm_prefetch(p + 2 * sizeof(Hbvh::LeafUnit) - 1, _MM_HINT_T0);
    }
  }
}

/// A leaf (Hbvh::LeafUnit's layout): its packets in pairs, then an odd last one. The lanes of a
/// pair are tested together, with AVX2 in one 8-wide test, without in two 4-wide ones with the
/// same result.
constexpr int kPairStride = Hbvh::kPairStride, kSingleStride = Hbvh::kSingleStride;
constexpr int kPairFloats = Hbvh::kLeafRows * kPairStride;

/// The id of lane `lane` of the packet (or pair) at `block`, `stride` floats a row.
inline uint32_t laneId(const float* block, int stride, int lane) {
  uint32_t id;
  std::memcpy(&id, block + Hbvh::kIdRow * stride + lane, sizeof id);
  return id;
}

/// Eight lanes of pair `block`: the mask of those hit, their t and barycentrics.
/// With kDefer, negative where a lane needs the scalar test (intersectPackets' kEdgeLanes).
template <bool kDefer>
inline int intersectPair(const float* block, const Ray& ray, const RayTriLanes& rl, float tMax, float* t, float* b1,
                         float* b2) {
#ifdef __AVX2__
  return intersectPackets<F8, kDefer>(block, kPairStride, ray, rl, tMax, t, b1, b2);
#else
  return intersectPackets<F4, kDefer>(block, kPairStride, ray, rl, tMax, t, b1, b2) |
         intersectPackets<F4, kDefer>(block + 4, kPairStride, ray, rl, tMax, t + 4, b1 + 4, b2 + 4) * 16;
#endif
}

/// Visit the leaf of `packets` packets at `leaf`: pair(block) for each pair, then single(block)
/// for an odd last packet, until one returns true (the result). The first pair is outside the
/// loop over pairs (a leaf of up to eight triangles has one): in a loop, GCC copied the ray's
/// lanes to the stack before it, once a leaf.
template <class PairFn, class SingleFn>
inline bool visitLeaf(const float* leaf, uint32_t packets, PairFn pair, SingleFn single) {
  const float* block = leaf;
  if (packets >= 2) {
    if (pair(block)) return true;
    block += kPairFloats;
    for (uint32_t p = 3; p < packets; p += 2, block += kPairFloats)
      if (pair(block)) return true;
  }
  return (packets & 1u) && single(block);
}

/// The next float above x >= 0 (x itself if infinite).
inline float nextUp(float x) {
  uint32_t bits;
  std::memcpy(&bits, &x, sizeof bits);
  bits += bits < 0x7f800000u;
  std::memcpy(&x, &bits, sizeof x);
  return x;
}

/// The leaf of `packets` packets at `leaf` against the closest-hit query so far (tMax, and hit
/// where found), a pair at a time, lanes in order. Of hits at the same distance the one of the
/// smaller triangle id wins, as in a brute-force loop over the ids: so the hit does not depend on
/// the order in which leaves are visited, which the kernels' box distances decide (rounded once
/// in the AVX2 and AVX-512 kernels, twice in the SSE ones), but only on which are visited; hence
/// a hit at tMax is a candidate once there is one (the packet test's limit the next float up).
/// With kDefer, returns true where a lane needs the scalar test, having stopped there (the caller
/// starts the ray again with the full kernel).
template <bool kDefer>
inline bool closerHitsLeaf(const float* leaf, uint32_t packets, const Ray& ray, const RayTriLanes& rl, float& tMax,
                           Hit& hit, bool& found) {
  alignas(32) float t[8], b1[8], b2[8];
  const auto take = [&](int mask, const float* block, int stride) {
    if (mask < 0) return true;  // kDefer's kEdgeLanes
    for (; mask; mask &= mask - 1) {
      const int i = __builtin_ctz(static_cast<unsigned>(mask));
      const uint32_t id = laneId(block, stride, i);
      if (t[i] < tMax || (t[i] == tMax && id < hit.triangle)) {  // at tMax only once found (the limit below)
        tMax = t[i];
        hit = {t[i], id, b1[i], b2[i]};
        found = true;
      }
    }
    return false;  // every packet of the leaf
  };
  const auto limit = [&] { return found ? nextUp(tMax) : tMax; };
  return visitLeaf(
      leaf, packets,
      [&](const float* block) {
        return take(intersectPair<kDefer>(block, ray, rl, limit(), t, b1, b2), block, kPairStride);
      },
      [&](const float* block) {
        return take(intersectPackets<F4, kDefer>(block, kSingleStride, ray, rl, limit(), t, b1, b2), block,
                    kSingleStride);
      });
}

/// Any hit in the leaf of `packets` packets at `leaf` in (tMin, tMax): 1 or 0; with kDefer, -1
/// where a lane needs the scalar test (the caller starts the ray again with the full kernel).
template <bool kDefer>
inline int anyHitLeaf(const float* leaf, uint32_t packets, const Ray& ray, const RayTriLanes& rl, float tMax) {
  alignas(32) float t[8], b1[8], b2[8];
  int result = 0;
  const auto stop = [&](int mask) {
    result = mask < 0 ? -1 : mask != 0;
    return mask != 0;
  };
  visitLeaf(
      leaf, packets, [&](const float* block) { return stop(intersectPair<kDefer>(block, ray, rl, tMax, t, b1, b2)); },
      [&](const float* block) {
        return stop(intersectPackets<F4, kDefer>(block, kSingleStride, ray, rl, tMax, t, b1, b2));
      });
  return result;
}

#if defined(__AVX2__) && !defined(__AVX512VL__)
/// Nibble k of kCompress.lanes[m] is the index of the k-th set bit of m: the permutation that
/// packs the lanes of mask m to the front, in order.
struct CompressTable {
  uint32_t lanes[1 << kWidth];
  constexpr CompressTable() : lanes() {
    for (int m = 0; m < (1 << kWidth); ++m)
      for (int i = 0, k = 0; i < kWidth; ++i)
        if ((m >> i) & 1) lanes[m] |= uint32_t(i) << (4 * k++);
  }
};
constexpr CompressTable kCompress;
#endif

/// Push a node's children `child` in `mask` onto the stack at sp, in index order, without a
/// branch per child: one permutation packs them to the front of a register and one store writes
/// all eight slots (the stack has room for them), of which sp keeps only the mask's.
inline uint32_t* pushChildren(uint32_t* sp, const uint32_t* child, int mask) {
#ifdef __AVX2__
  static_assert(offsetof(Node, child) % 32 == 0 && alignof(Node) % 32 == 0, "a node's refs are one aligned load");
  static_assert(offsetof(QNode, child) % 32 == 0 && alignof(QNode) % 32 == 0, "a node's refs are one aligned load");
  const __m256i refs = _mm256_load_si256(reinterpret_cast<const __m256i*>(child));
#ifdef __AVX512VL__
  // vpcompressd into a register (to memory it is microcoded on AMD's Zen 4).
  const __m256i packed = _mm256_maskz_compress_epi32(__mmask8(mask), refs);
#else
  // vpermd reads the low three bits of each index: the nibbles need no masking.
  const __m256i idx = _mm256_srlv_epi32(_mm256_set1_epi32(int(kCompress.lanes[mask])),
                                        _mm256_setr_epi32(0, 4, 8, 12, 16, 20, 24, 28));
  const __m256i packed = _mm256_permutevar8x32_epi32(refs, idx);
#endif
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(sp), packed);
  return sp + __builtin_popcount(static_cast<unsigned>(mask));
#else
  for (int i = 0; i < kWidth; ++i) {
    *sp = child[i];
    sp += (mask >> i) & 1;
  }
  return sp;
#endif
}

/// The child in `mask` whose entry distance is the largest, the first of equals (distances
/// ordered as integers, as slabTest does). Scalar, with conditional moves: an AVX2 horizontal
/// maximum was 2-3% slower on the dragon's shadow rays.
inline int farthestChild(const float* tNear, int mask) {
  int best = __builtin_ctz(static_cast<unsigned>(mask));
  int32_t bestT;
  std::memcpy(&bestT, tNear + best, sizeof bestT);
  for (int m = mask & (mask - 1); m; m &= m - 1) {
    const int i = __builtin_ctz(static_cast<unsigned>(m));
    int32_t ti;
    std::memcpy(&ti, tNear + i, sizeof ti);
    const bool better = ti > bestT;
    best = better ? i : best;
    bestT = better ? ti : bestT;
  }
  return best;
}

/// Stack depth: at most kWidth - 1 entries per level of the path; the 8-wide tree is no deeper
/// than the binary one, whose depth stays below kMaxDepth + log2(triangles) = 60 + 25 (the
/// build), rounded up to 96.
constexpr int kStackSize = (kWidth - 1) * 96 + kWidth;  // + kWidth: occlusion writes every slot past the top

}  // namespace

#ifdef VOXCONE_HBVH_COUNTERS
#define VOXCONE_COUNT(field, n) (hbvhCounters().field += (n))
#else
#define VOXCONE_COUNT(field, n) ((void)0)
#endif

/// A closest-hit stack entry: a child and its entry distance, in one 64-bit word whose signed
/// order is the distance's (the float's bits above the reference; entry distances are at least
/// tMin, so never negative but for -0, which orders as nearest), ties by reference. Ordering
/// by the word needs no branch: compilers make conditional moves of the exchanges below.
using Entry = int64_t;
inline Entry makeEntry(uint32_t ref, float t) {
  uint32_t bits;
  std::memcpy(&bits, &t, sizeof bits);
  return Entry((uint64_t(bits) << 32) | ref);
}
inline uint32_t entryRef(Entry e) { return uint32_t(uint64_t(e)); }
inline float entryT(Entry e) {
  const uint32_t bits = uint32_t(uint64_t(e) >> 32);
  float t;
  std::memcpy(&t, &bits, sizeof t);
  return t;
}
/// a, deeper in the stack, takes the farther of the two.
inline void farFirst(Entry& a, Entry& b) {
  const Entry lo = a < b ? a : b, hi = a < b ? b : a;
  a = hi;
  b = lo;
}

namespace {

/// BoxRay: PaddedBoxRay where paddedBoxesHold (checked here: other rays go on with the robust
/// test), RobustBoxRay. kFull: the kernel for every tree. Without, for trees without spheres
/// (Hbvh::intersect chooses, the hbvh*Lean entry points): a leaf lane that needs the scalar test
/// (an edge function exactly zero, rare) starts the ray again with the full kernel, so that the
/// loop holds no call and GCC keeps the ray's constants in registers rather than reloading them
/// from the stack at every node.
template <class BoxRay, bool kFull>
std::optional<Hit> intersectWith(const HbvhArrays& bvh, const Ray& ray) {
  if constexpr (std::is_same_v<BoxRay, PaddedBoxRay>) {
    if (__builtin_expect(!paddedBoxesHold(bvh, ray), 0)) return intersectWith<RobustBoxRay, true>(bvh, ray);
  }
  const BoxRay rd(ray);
  SphereRay sr;
  LeafRay leafRay;
  const float tMin = ray.tMin;
  Hit hit;
  float tMax = ray.tMax;
  bool found = false;

  Entry stack[kStackSize];
  Entry* sp = stack;
  uint32_t cur = 0;  // the root node
  for (;;) {
    // Down the inner nodes to a leaf, or to a node none of whose children the ray enters.
    while (!(cur & kLeafBit)) {
      VOXCONE_COUNT(nodes, 1);
      alignas(32) float tNear[kWidth];
      const uint32_t* child;
      int mask = enterNode<kFull>(bvh, cur, ray, rd, sr, tMin, tMax, tNear, child);
      if (mask == 0) goto pop;
      // One child entered: go on with it; two: push the farther; three or four: push all, sort
      // them farthest first by a sorting network and pop the nearest; more: insertion sort (as
      // Embree's BVHNNodeTraverser1Hit, here without branches on the distances).
      const int i0 = __builtin_ctz(static_cast<unsigned>(mask));
      mask &= mask - 1;
      if (mask == 0) {
        cur = child[i0];
        continue;
      }
      prefetchChildren(bvh, child, mask | (1 << i0));
      const int i1 = __builtin_ctz(static_cast<unsigned>(mask));
      mask &= mask - 1;
      if (mask == 0) {
        const bool firstNearer = tNear[i0] <= tNear[i1];
        const int nearI = firstNearer ? i0 : i1, farI = firstNearer ? i1 : i0;
        *sp++ = makeEntry(child[farI], tNear[farI]);
        cur = child[nearI];
        continue;
      }
      Entry* const base = sp;
      *sp++ = makeEntry(child[i0], tNear[i0]);
      *sp++ = makeEntry(child[i1], tNear[i1]);
      for (; mask; mask &= mask - 1) {
        const int i = __builtin_ctz(static_cast<unsigned>(mask));
        *sp++ = makeEntry(child[i], tNear[i]);
      }
      const long count = sp - base;
      if (count == 3) {
        farFirst(base[0], base[1]);
        farFirst(base[1], base[2]);
        farFirst(base[0], base[1]);
      } else if (count == 4) {
        farFirst(base[0], base[1]);
        farFirst(base[2], base[3]);
        farFirst(base[0], base[2]);
        farFirst(base[1], base[3]);
        farFirst(base[1], base[2]);
      } else {
        for (Entry* j = base + 1; j < sp; ++j) {
          const Entry e = *j;
          Entry* k = j;
          for (; k > base && k[-1] < e; --k) *k = k[-1];
          *k = e;
        }
      }
      cur = entryRef(*--sp);
    }
    {
      // Leaf: test its packets, shrinking tMax to the nearest hit.
      VOXCONE_COUNT(leaves, 1);
      VOXCONE_COUNT(packets, leafPackets(cur));
      if (closerHitsLeaf<!kFull>(bvh.leaf(leafFirst(cur)), leafPackets(cur), ray, leafRay.get(ray), tMax, hit, found))
        return intersectWith<BoxRay, true>(bvh, ray);
    }
  pop:
    // The next child still in front of the closest hit.
    for (;;) {
      if (sp == stack) return found ? std::optional<Hit>(hit) : std::nullopt;
      --sp;
      if (entryT(*sp) <= tMax) {
        cur = entryRef(*sp);
        break;
      }
    }
  }
}

template <class BoxRay, bool kFull>
bool occludedWith(const HbvhArrays& bvh, const Ray& ray, float tMax) {
  if constexpr (std::is_same_v<BoxRay, PaddedBoxRay>) {
    if (__builtin_expect(!paddedBoxesHold(bvh, ray), 0)) return occludedWith<RobustBoxRay, true>(bvh, ray, tMax);
  }
  const BoxRay rd(ray);
  SphereRay sr;
  LeafRay leafRay;
  const float tMin = ray.tMin;
  uint32_t stack[kStackSize];
  uint32_t* sp = stack;
  uint32_t cur = 0;
  for (;;) {
    while (!(cur & kLeafBit)) {
      VOXCONE_COUNT(nodes, 1);
      alignas(32) float tNear[kWidth];
      const uint32_t* child;
      int mask = enterNode<kFull>(bvh, cur, ray, rd, sr, tMin, tMax, tNear, child);
      if (mask == 0) goto pop;
      // Any hit ends the query: go on with the child most likely to hold one, push the rest.
      // Below a full Node that is the farthest: a shadow ray leaves a surface, and the boxes
      // around its origin are the ones sure to be entered and likely to hold nothing it hits
      // (bench/hbvh_vs_embree, occlusion, ratio to Embree, 4 alternating runs, medians: 10M knot
      // 1.02 -> 1.13, dragon 1.05 -> 1.05; nearest first: dragon 0.83, knot 0.90). Below a QNode,
      // whose children are mostly its leaves, laid out after it, the first: farthest there too
      // took the dragon to 1.02 (its leaves are tested in fewer numbers but out of order).
      const int first = __builtin_ctz(static_cast<unsigned>(mask));
      const int next = (cur & kQuantBit) || !(mask & (mask - 1)) ? first : farthestChild(tNear, mask);
      cur = child[next];
      sp = pushChildren(sp, child, mask & ~(1 << next));
    }
    {
      VOXCONE_COUNT(leaves, 1);
      VOXCONE_COUNT(packets, leafPackets(cur));
      const int hit = anyHitLeaf<!kFull>(bvh.leaf(leafFirst(cur)), leafPackets(cur), ray, leafRay.get(ray), tMax);
      if (hit > 0) return true;
      if (hit < 0) return occludedWith<BoxRay, true>(bvh, ray, tMax);
    }
  pop:
    if (sp == stack) return false;
    cur = *--sp;
    if (sp != stack) prefetchRef(bvh, sp[-1]);
  }
}

}  // namespace

std::optional<Hit> hbvhIntersect(const HbvhArrays& bvh, const Ray& ray) {
  return intersectWith<PaddedBoxRay, true>(bvh, ray);
}
std::optional<Hit> hbvhIntersectLean(const HbvhArrays& bvh, const Ray& ray) {
  return intersectWith<PaddedBoxRay, false>(bvh, ray);
}
bool hbvhOccluded(const HbvhArrays& bvh, const Ray& ray, float tMax) {
  return occludedWith<PaddedBoxRay, true>(bvh, ray, tMax);
}
bool hbvhOccludedLean(const HbvhArrays& bvh, const Ray& ray, float tMax) {
  return occludedWith<PaddedBoxRay, false>(bvh, ray, tMax);
}

}  // namespace VOXCONE_ISA
}  // namespace voxcone

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
// share an inline function (the linker would keep one of them for all). The lanes and the box
// and sphere tests are in hbvh_box_tests.h.

#ifndef VOXCONE_ISA
#error "define VOXCONE_ISA (sse42, avx2 or avx512) before including hbvh_traverse_kernel.h"
#endif

#include "hbvh_box_tests.h"
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

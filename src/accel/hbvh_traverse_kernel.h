// HBVH traversal over 8-wide nodes, compiled once per instruction set (hbvh_kernels.h): the
// eight child boxes of a node are tested at once, in one AVX register per plane where __AVX2__
// is defined and in two SSE halves where not, with the same operations in the same order (no
// FMA: the AVX2 TU is built with -mavx2 alone), so both kernels give the same hits bit for bit.
// The box test is the robust slab test (Ize 2013, "Robust BVH Ray Traversal", JCGT 2(2): the
// exit distance is widened by 1 + 2 gamma(3)); a child that keeps a bounding sphere must also be
// entered by the ray's sphere interval. Closest-hit traversal visits the hit children nearest
// first. Everything here lives in namespace voxcone::VOXCONE_ISA, so that the two compilations
// never share an inline function (the linker would keep one of them for both).

#ifndef VOXCONE_ISA
#error "define VOXCONE_ISA (sse42 or avx2) before including hbvh_traverse_kernel.h"
#endif

#include "hbvh_kernels.h"
#include "triangle4_sse.h"

#include <immintrin.h>

#include <cstddef>

namespace voxcone {
namespace VOXCONE_ISA {

namespace {

using Node = Hbvh::Node;
constexpr int kWidth = Hbvh::kWidth;
constexpr uint32_t kLeafBit = Hbvh::kLeafBit, kCountShift = Hbvh::kCountShift, kSlotMask = Hbvh::kSlotMask;

/// 1 + 2 gamma(3) (Ize 2013, sec. 3.3).
constexpr float kSlabScale = 1.0f + 2.0f * (3.0f * 0x1p-24f) / (1.0f - 3.0f * 0x1p-24f);

#ifdef __AVX2__
using VFloat = __m256;  ///< one plane of all eight children
inline VFloat broadcast(float x) { return _mm256_set1_ps(x); }
#else
using VFloat = __m128;  ///< one plane of four children (a node takes two)
inline VFloat broadcast(float x) { return _mm_set1_ps(x); }
#endif

/// Per-ray constants of the box and sphere tests.
struct RayData {
  VFloat org[3], invDir[3];
  // Per axis: byte offsets in a Node of the entry and exit planes (lo or hi by the sign of the
  // direction), so the box test has no branch.
  size_t nearOffset[3], farOffset[3];
  const Ray& ray;
  explicit RayData(const Ray& r) : ray(r) {
    for (int a = 0; a < 3; ++a) {
      // A zero component becomes a tiny one so that 0 * inf never makes a NaN distance.
      float d = r.dir[a];
      if (std::fabs(d) < 1e-30f) d = std::copysign(1e-30f, d);
      org[a] = broadcast(r.origin[a]);
      invDir[a] = broadcast(1.0f / d);
      const size_t lo = offsetof(Node, lo) + a * sizeof(float[kWidth]);
      const size_t hi = offsetof(Node, hi) + a * sizeof(float[kWidth]);
      nearOffset[a] = d < 0.0f ? hi : lo;
      farOffset[a] = d < 0.0f ? lo : hi;
    }
  }
};

/// The sphere test's per-ray constants (a square root and a division), made on the first sphere
/// a ray meets: few children keep one (123 of the dragon's 217k).
struct SphereRay {
  Vec3 dirUnit{0.0f};
  float invLen = 0.0f;  ///< 0 until made
  void make(const Ray& r) {
    invLen = 1.0f / glm::length(r.dir);
    dirUnit = r.dir * invLen;
  }
};

/// The slab test of the children from `first` on, one register wide: their entry distances
/// into tNearOut[first..] and the mask of those entered, from bit 0.
inline int enterBoxes(const Node& n, int first, const RayData& rd, float tMin, float tMax, float* tNearOut) {
  const char* base = reinterpret_cast<const char*>(&n) + first * sizeof(float);
  VFloat tNear = broadcast(tMin), tFar = broadcast(kInf);
#ifdef __AVX2__
  for (int a = 0; a < 3; ++a) {
    const VFloat nearPlane = _mm256_load_ps(reinterpret_cast<const float*>(base + rd.nearOffset[a]));
    const VFloat farPlane = _mm256_load_ps(reinterpret_cast<const float*>(base + rd.farOffset[a]));
    tNear = _mm256_max_ps(tNear, _mm256_mul_ps(_mm256_sub_ps(nearPlane, rd.org[a]), rd.invDir[a]));
    tFar = _mm256_min_ps(tFar, _mm256_mul_ps(_mm256_sub_ps(farPlane, rd.org[a]), rd.invDir[a]));
  }
  tFar = _mm256_min_ps(_mm256_mul_ps(tFar, broadcast(kSlabScale)), broadcast(tMax));
  _mm256_storeu_ps(tNearOut + first, tNear);
  return _mm256_movemask_ps(_mm256_cmp_ps(tNear, tFar, _CMP_LE_OQ));
#else
  for (int a = 0; a < 3; ++a) {
    const VFloat nearPlane = _mm_load_ps(reinterpret_cast<const float*>(base + rd.nearOffset[a]));
    const VFloat farPlane = _mm_load_ps(reinterpret_cast<const float*>(base + rd.farOffset[a]));
    tNear = _mm_max_ps(tNear, _mm_mul_ps(_mm_sub_ps(nearPlane, rd.org[a]), rd.invDir[a]));
    tFar = _mm_min_ps(tFar, _mm_mul_ps(_mm_sub_ps(farPlane, rd.org[a]), rd.invDir[a]));
  }
  tFar = _mm_min_ps(_mm_mul_ps(tFar, broadcast(kSlabScale)), broadcast(tMax));
  _mm_storeu_ps(tNearOut + first, tNear);
  return _mm_movemask_ps(_mm_cmple_ps(tNear, tFar));
#endif
}

/// Entry distances of the eight children (+inf where missed) and the mask of those entered.
inline int enterChildren(const Node& n, const Vec4* spheres, const RayData& rd, SphereRay& sr, float tMin,
                         float tMax, float tNearOut[kWidth]) {
#ifdef __AVX2__
  int mask = enterBoxes(n, 0, rd, tMin, tMax, tNearOut);
#else
  int mask = enterBoxes(n, 0, rd, tMin, tMax, tNearOut) | enterBoxes(n, 4, rd, tMin, tMax, tNearOut) << 4;
#endif
  if (mask & n.sphereMask) {
    // Spheres: distance of closest approach along the unit direction (Haines et al.,
    // "Precision Improvements for Ray/Sphere Intersection", Ray Tracing Gems ch. 7).
    if (sr.invLen == 0.0f) sr.make(rd.ray);
    uint32_t sphereIdx = n.sphereBase;
    for (int i = 0; i < kWidth; ++i) {
      if (!(n.sphereMask & (1u << i))) continue;
      const Vec4& s = spheres[sphereIdx++];
      if (!(mask & (1 << i))) continue;
      const Vec3 f = rd.ray.origin - Vec3(s);
      const float b = -glm::dot(f, sr.dirUnit);
      const Vec3 l = f + b * sr.dirUnit;
      // Rounding in l grows with |f|, not with the radius: widen the radius by 1e-6 |f|.
      const float rEff = s.w + 1e-6f * std::sqrt(glm::dot(f, f));
      const float disc = rEff * rEff - glm::dot(l, l);
      bool hit = disc >= 0.0f;
      if (hit) {
        const float h = std::sqrt(disc);
        const float sNear = (b - h) * sr.invLen, sFar = (b + h) * sr.invLen;
        tNearOut[i] = tNearOut[i] < sNear ? sNear : tNearOut[i];  // std::max
        hit = tNearOut[i] <= (tMax < sFar ? tMax : sFar) && sFar >= tMin;  // std::min, inline here
      }
      if (!hit) mask &= ~(1 << i);
    }
  }
  return mask;
}

/// Start loading the entered children (the first 3 of a node's 4 lines, a leaf's first packet
/// and a half) while their order is worked out: a third of the kernel's samples wait on those
/// loads. Measured: about +3% on incoherent rays, the other sets within the run-to-run noise.
inline void prefetchChildren(const HbvhArrays& bvh, const Node& n, int mask) {
  for (; mask; mask &= mask - 1) {
    const uint32_t c = n.child[__builtin_ctz(static_cast<unsigned>(mask))];
    const char* p = (c & kLeafBit) ? reinterpret_cast<const char*>(bvh.tris + (c & kSlotMask))
                                   : reinterpret_cast<const char*>(bvh.nodes + c);
    _mm_prefetch(p, _MM_HINT_T0);
    _mm_prefetch(p + 64, _MM_HINT_T0);
    _mm_prefetch(p + 128, _MM_HINT_T0);
  }
}

/// Stack depth: at most kWidth - 1 entries per level of the path; the 8-wide tree is no deeper
/// than the binary one, whose depth stays below kMaxDepth + log2(triangles) = 60 + 25 (the
/// build), rounded up to 96.
constexpr int kStackSize = (kWidth - 1) * 96;

}  // namespace

std::optional<Hit> hbvhIntersect(const HbvhArrays& bvh, const Ray& ray) {
  const RayData rd(ray);
  SphereRay sr;
  const RayTri4 rt(ray);
  const Node* nodes = bvh.nodes;
  Hit hit;
  float tMax = ray.tMax;
  bool found = false;

  struct Entry {
    uint32_t ref;
    float t;
  };
  Entry stack[kStackSize];
  int sp = 0;
  uint32_t cur = 0;  // the root node
  for (;;) {
    if (cur & kLeafBit) {
      // Leaf: test its packets, shrinking tMax to the nearest hit.
      const uint32_t first = cur & kSlotMask, count = ((cur & ~kLeafBit) >> kCountShift) + 1u;
      found |= closerHits(bvh.tris + first, count, ray, rt, tMax, hit);
    } else {
      const Node& n = nodes[cur];
      alignas(32) float tNear[kWidth];
      int mask = enterChildren(n, bvh.spheres, rd, sr, ray.tMin, tMax, tNear);
      if (mask != 0) {
        prefetchChildren(bvh, n, mask);
        // One child entered: go on with it; two: push the farther; more: push all, sort them
        // farthest first and pop the nearest (as Embree's BVHNNodeTraverser1Hit).
        const int i0 = __builtin_ctz(static_cast<unsigned>(mask));
        mask &= mask - 1;
        if (mask == 0) {
          cur = n.child[i0];
          continue;
        }
        const int i1 = __builtin_ctz(static_cast<unsigned>(mask));
        mask &= mask - 1;
        if (mask == 0) {
          const bool firstNearer = tNear[i0] <= tNear[i1];
          const int nearI = firstNearer ? i0 : i1, farI = firstNearer ? i1 : i0;
          stack[sp++] = {n.child[farI], tNear[farI]};
          cur = n.child[nearI];
          continue;
        }
        const int base = sp;
        stack[sp++] = {n.child[i0], tNear[i0]};
        stack[sp++] = {n.child[i1], tNear[i1]};
        for (; mask; mask &= mask - 1) {
          const int i = __builtin_ctz(static_cast<unsigned>(mask));
          stack[sp++] = {n.child[i], tNear[i]};
        }
        for (int j = base + 1; j < sp; ++j) {
          const Entry e = stack[j];
          int k = j;
          for (; k > base && stack[k - 1].t < e.t; --k) stack[k] = stack[k - 1];
          stack[k] = e;
        }
        cur = stack[--sp].ref;
        continue;
      }
    }
    // Pop the next child still in front of the closest hit.
    for (;;) {
      if (sp == 0) return found ? std::optional<Hit>(hit) : std::nullopt;
      const Entry e = stack[--sp];
      if (e.t <= tMax) {
        cur = e.ref;
        break;
      }
    }
  }
}

bool hbvhOccluded(const HbvhArrays& bvh, const Ray& ray, float tMax) {
  const RayData rd(ray);
  SphereRay sr;
  const RayTri4 rt(ray);
  const Node* nodes = bvh.nodes;
  uint32_t stack[kStackSize];
  int sp = 0;
  uint32_t cur = 0;
  for (;;) {
    if (cur & kLeafBit) {
      const uint32_t first = cur & kSlotMask, count = ((cur & ~kLeafBit) >> kCountShift) + 1u;
      if (anyHit(bvh.tris + first, count, ray, rt, tMax)) return true;
    } else {
      const Node& n = nodes[cur];
      alignas(32) float tNear[kWidth];
      int mask = enterChildren(n, bvh.spheres, rd, sr, ray.tMin, tMax, tNear);
      if (mask != 0) {
        // Any hit ends the query, so order does not matter: take the first, push the rest.
        cur = n.child[__builtin_ctz(static_cast<unsigned>(mask))];
        mask &= mask - 1;
        while (mask) {
          stack[sp++] = n.child[__builtin_ctz(static_cast<unsigned>(mask))];
          mask &= mask - 1;
        }
        continue;
      }
    }
    if (sp == 0) return false;
    cur = stack[--sp];
  }
}

}  // namespace VOXCONE_ISA
}  // namespace voxcone

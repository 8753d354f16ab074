// HBVH traversal over 4-wide nodes. The four child boxes of a node are tested at once with SSE
// (robust slab test, Ize 2013, "Robust BVH Ray Traversal", JCGT 2(2): the exit distance is
// widened by 1 + 2 gamma(3)); a child that keeps a bounding sphere must also be entered by the
// ray's sphere interval. Closest-hit traversal visits the hit children nearest first.

#include "voxcone/accel/hbvh.h"
#include "triangle4_sse.h"

#include <smmintrin.h>

#include <cstddef>

namespace voxcone {

namespace {

/// 1 + 2 gamma(3) (Ize 2013, sec. 3.3).
constexpr float kSlabScale = 1.0f + 2.0f * (3.0f * 0x1p-24f) / (1.0f - 3.0f * 0x1p-24f);

/// Per-ray constants of the box and sphere tests.
struct RayData {
  __m128 org[3], invDir[3];
  // Per axis: byte offsets in a Node4 of the entry and exit planes (lo or hi by the sign of
  // the direction), so the box test has no branch.
  size_t nearOffset[3], farOffset[3];
  Vec3 origin, dirUnit;
  float invLen;
  explicit RayData(const Ray& r) : origin(r.origin) {
    for (int a = 0; a < 3; ++a) {
      // A zero component becomes a tiny one so that 0 * inf never makes a NaN distance.
      float d = r.dir[a];
      if (std::fabs(d) < 1e-30f) d = std::copysign(1e-30f, d);
      org[a] = _mm_set1_ps(r.origin[a]);
      invDir[a] = _mm_set1_ps(1.0f / d);
      const size_t lo = offsetof(Hbvh::Node4, lo) + a * sizeof(float[4]);
      const size_t hi = offsetof(Hbvh::Node4, hi) + a * sizeof(float[4]);
      nearOffset[a] = d < 0.0f ? hi : lo;
      farOffset[a] = d < 0.0f ? lo : hi;
    }
    const float len = glm::length(r.dir);
    invLen = 1.0f / len;
    dirUnit = r.dir * invLen;
  }
};

/// Entry distances of the four children (+inf where missed) and the mask of those entered.
inline int enterChildren(const Hbvh::Node4& n, const Vec4* spheres, const RayData& rd, float tMin, float tMax,
                         float tNearOut[4]) {
  __m128 tNear = _mm_set1_ps(tMin);
  __m128 tFar = _mm_set1_ps(kInf);
  for (int a = 0; a < 3; ++a) {
    const char* base = reinterpret_cast<const char*>(&n);
    const __m128 nearPlane = _mm_load_ps(reinterpret_cast<const float*>(base + rd.nearOffset[a]));
    const __m128 farPlane = _mm_load_ps(reinterpret_cast<const float*>(base + rd.farOffset[a]));
    tNear = _mm_max_ps(tNear, _mm_mul_ps(_mm_sub_ps(nearPlane, rd.org[a]), rd.invDir[a]));
    tFar = _mm_min_ps(tFar, _mm_mul_ps(_mm_sub_ps(farPlane, rd.org[a]), rd.invDir[a]));
  }
  tFar = _mm_min_ps(_mm_mul_ps(tFar, _mm_set1_ps(kSlabScale)), _mm_set1_ps(tMax));
  int mask = _mm_movemask_ps(_mm_cmple_ps(tNear, tFar));
  _mm_storeu_ps(tNearOut, tNear);
  if (mask & n.sphereMask) {
    // Spheres: distance of closest approach along the unit direction (Haines et al.,
    // "Precision Improvements for Ray/Sphere Intersection", Ray Tracing Gems ch. 7).
    uint32_t sphereIdx = n.sphereBase;
    for (int i = 0; i < 4; ++i) {
      if (!(n.sphereMask & (1u << i))) continue;
      const Vec4& s = spheres[sphereIdx++];
      if (!(mask & (1 << i))) continue;
      const Vec3 f = rd.origin - Vec3(s);
      const float b = -glm::dot(f, rd.dirUnit);
      const Vec3 l = f + b * rd.dirUnit;
      // Rounding in l grows with |f|, not with the radius: widen the radius by 1e-6 |f|.
      const float rEff = s.w + 1e-6f * std::sqrt(glm::dot(f, f));
      const float disc = rEff * rEff - glm::dot(l, l);
      bool hit = disc >= 0.0f;
      if (hit) {
        const float h = std::sqrt(disc);
        const float sNear = (b - h) * rd.invLen, sFar = (b + h) * rd.invLen;
        tNearOut[i] = std::max(tNearOut[i], sNear);
        hit = tNearOut[i] <= std::min(sFar, tMax) && sFar >= tMin;
      }
      if (!hit) mask &= ~(1 << i);
    }
  }
  return mask;
}

/// Stack depth: at most 3 entries per 4-wide level; levels < 60 + log2(2^25) (see the build).
constexpr int kStackSize = 256;

}  // namespace

std::optional<Hit> Hbvh::intersect(const Ray& ray) const {
  if (m_nodes.empty()) return std::nullopt;
  const RayData rd(ray);
  const RayTri4 rt(ray);
  const Node4* nodes = m_nodes.data();
  const Vec4* spheres = m_spheres.data();
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
      for (uint32_t p = first; p < first + count; ++p) found |= closerHit(m_tris[p], ray, rt, tMax, hit);
    } else {
      const Node4& n = nodes[cur];
      float tNear[4];
      int mask = enterChildren(n, spheres, rd, ray.tMin, tMax, tNear);
      if (mask != 0) {
        // Push the entered children farthest first; continue with the nearest.
        int order[4], k = 0;
        while (mask) {
          const int i = __builtin_ctz(static_cast<unsigned>(mask));
          mask &= mask - 1;
          int j = k++;
          while (j > 0 && tNear[order[j - 1]] < tNear[i]) {
            order[j] = order[j - 1];
            --j;
          }
          order[j] = i;
        }
        for (int j = 0; j < k - 1; ++j) stack[sp++] = {n.child[order[j]], tNear[order[j]]};
        cur = n.child[order[k - 1]];
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

bool Hbvh::occluded(const Ray& ray, float tMax) const {
  if (m_nodes.empty()) return false;
  const RayData rd(ray);
  const RayTri4 rt(ray);
  const Node4* nodes = m_nodes.data();
  const Vec4* spheres = m_spheres.data();
  uint32_t stack[kStackSize];
  int sp = 0;
  uint32_t cur = 0;
  for (;;) {
    if (cur & kLeafBit) {
      const uint32_t first = cur & kSlotMask, count = ((cur & ~kLeafBit) >> kCountShift) + 1u;
      for (uint32_t p = first; p < first + count; ++p) {
        float t[4], b1[4], b2[4];
        if (intersectTriangle4(m_tris[p], ray, rt, ray.tMin, tMax, t, b1, b2)) return true;
      }
    } else {
      const Node4& n = nodes[cur];
      float tNear[4];
      int mask = enterChildren(n, spheres, rd, ray.tMin, tMax, tNear);
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

}  // namespace voxcone

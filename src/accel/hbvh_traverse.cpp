// HBVH traversal over 4-wide nodes. The four child boxes of a node are tested at once with SSE
// (robust slab test, Ize 2013, "Robust BVH Ray Traversal", JCGT 2(2): the exit distance is
// widened by 1 + 2 gamma(3)); a child that keeps a bounding sphere must also be entered by the
// ray's sphere interval. Closest-hit traversal visits the hit children nearest first.

#include "voxcone/accel/hbvh.h"
#include "voxcone/accel/triangle.h"

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
inline int intersectTriangle4(const Hbvh::Triangle4& tri, const Ray& ray, const RayTri4& rt, float tMin, float tMax,
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
    _mm_storeu_ps(tOut, _mm_mul_ps(tScaled, invDet));
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
      for (uint32_t p = first; p < first + count; ++p) {
        float t[4], b1[4], b2[4];
        int mask = intersectTriangle4(m_tris[p], ray, rt, ray.tMin, tMax, t, b1, b2);
        for (; mask; mask &= mask - 1) {
          const int i = __builtin_ctz(static_cast<unsigned>(mask));
          if (t[i] < tMax) {
            tMax = t[i];
            hit = {t[i], m_tris[p].id[i], b1[i], b2[i]};
            found = true;
          }
        }
      }
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

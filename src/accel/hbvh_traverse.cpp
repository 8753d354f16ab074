// HBVH traversal: ordered depth-first with an explicit stack. A child is entered when the ray
// passes its AABB (robust slab test, Ize 2013, "Robust BVH Ray Traversal", JCGT 2(2)) and, if
// it keeps one, its bounding sphere; the entry distance is the later of the two.

#include "voxcone/accel/hbvh.h"
#include "voxcone/accel/triangle.h"

namespace voxcone {

namespace {

/// Per-ray constants of the box and sphere tests.
struct RayBoxData {
  Vec3 org, invDir, dirUnit;
  float invLen;
  explicit RayBoxData(const Ray& r) : org(r.origin) {
    // A zero component becomes a tiny one so that 0 * inf never makes a NaN slab distance.
    Vec3 d = r.dir;
    for (int i = 0; i < 3; ++i)
      if (std::fabs(d[i]) < 1e-30f) d[i] = std::copysign(1e-30f, d[i]);
    invDir = 1.0f / d;
    const float len = glm::length(r.dir);
    invLen = 1.0f / len;
    dirUnit = r.dir * invLen;
  }
};

/// 1 + 2 gamma(3): widens the slab exit so that rounding never misses a box the exact
/// ray passes (Ize 2013, sec. 3.3).
constexpr float kSlabScale = 1.0f + 2.0f * (3.0f * 0x1p-24f) / (1.0f - 3.0f * 0x1p-24f);

/// Entry distance into the node's volume within [tMin, tMax], or +inf when missed.
inline float enterNode(const Hbvh::Node& n, const Vec4* spheres, const RayBoxData& rb, float tMin, float tMax) {
  const Vec3 t0 = (n.lo - rb.org) * rb.invDir;
  const Vec3 t1 = (n.hi - rb.org) * rb.invDir;
  const Vec3 tn = glm::min(t0, t1), tf = glm::max(t0, t1);
  const float tNear = std::max(std::max(tn.x, tn.y), std::max(tn.z, tMin));
  const float tFar = std::min(std::min(tf.x, tf.y), tf.z) * kSlabScale;
  if (!(tNear <= std::min(tFar, tMax))) return kInf;
  const uint32_t sphere = n.sphereIndexPlusOne();
  if (sphere == 0) return tNear;
  // Sphere: distance of closest approach along the unit direction (Haines et al., "Precision
  // Improvements for Ray/Sphere Intersection", Ray Tracing Gems ch. 7), in units of |dir|.
  const Vec4& s = spheres[sphere - 1];
  const Vec3 f = rb.org - Vec3(s);
  const float b = -glm::dot(f, rb.dirUnit);
  const Vec3 l = f + b * rb.dirUnit;
  // Rounding in l grows with the distance |f| to the centre, not with the radius: widen the
  // radius by 1e-6 |f| (several ulps of |f|) so a ray grazing a vertex on the sphere is kept.
  const float rEff = s.w + 1e-6f * std::sqrt(glm::dot(f, f));
  const float disc = rEff * rEff - glm::dot(l, l);
  if (disc < 0.0f) return kInf;
  const float h = std::sqrt(disc);
  const float sNear = (b - h) * rb.invLen, sFar = (b + h) * rb.invLen;
  const float enter = std::max(tNear, sNear);
  if (enter > std::min(sFar, tMax) || sFar < tMin) return kInf;
  return enter;
}

}  // namespace

std::optional<Hit> Hbvh::intersect(const Ray& ray) const {
  if (m_nodes.empty()) return std::nullopt;
  const RayBoxData rb(ray);
  const WatertightRay wr(ray.dir);
  const Node* nodes = m_nodes.data();
  const Vec4* spheres = m_spheres.data();
  Hit hit;
  float tMax = ray.tMax;
  bool found = false;

  struct Entry {
    uint32_t node;
    float t;
  };
  Entry stack[64];
  int sp = 0;
  if (enterNode(nodes[0], spheres, rb, ray.tMin, tMax) == kInf) return std::nullopt;
  uint32_t cur = 0;
  for (;;) {
    const Node& n = nodes[cur];
    const uint32_t count = n.triangleCount();
    if (count > 0) {
      // Leaf: test its triangles, shrinking tMax.
      const Vec3* v = &m_triVerts[3 * size_t(n.offset)];
      for (uint32_t i = 0; i < count; ++i, v += 3) {
        float t, b1, b2;
        if (intersectTriangleWatertight(ray.origin, wr, v[0], v[1], v[2], ray.tMin, tMax, t, b1, b2)) {
          tMax = t;
          hit.t = t;
          hit.b1 = b1;
          hit.b2 = b2;
          hit.triangle = m_triIds[n.offset + i];
          found = true;
        }
      }
    } else {
      // Interior: visit the nearer child first, keep the other on the stack.
      const uint32_t l = cur + 1, r = n.offset;
      const float tl = enterNode(nodes[l], spheres, rb, ray.tMin, tMax);
      const float tr = enterNode(nodes[r], spheres, rb, ray.tMin, tMax);
      if (tl != kInf && tr != kInf) {
        if (tl <= tr) {
          stack[sp++] = {r, tr};
          cur = l;
        } else {
          stack[sp++] = {l, tl};
          cur = r;
        }
        continue;
      }
      if (tl != kInf) {
        cur = l;
        continue;
      }
      if (tr != kInf) {
        cur = r;
        continue;
      }
    }
    // Pop the next node still in front of the closest hit.
    for (;;) {
      if (sp == 0) return found ? std::optional<Hit>(hit) : std::nullopt;
      const Entry e = stack[--sp];
      if (e.t <= tMax) {
        cur = e.node;
        break;
      }
    }
  }
}

bool Hbvh::occluded(const Ray& ray, float tMaxIn) const {
  if (m_nodes.empty()) return false;
  const RayBoxData rb(ray);
  const WatertightRay wr(ray.dir);
  const Node* nodes = m_nodes.data();
  const Vec4* spheres = m_spheres.data();
  uint32_t stack[64];
  int sp = 0;
  if (enterNode(nodes[0], spheres, rb, ray.tMin, tMaxIn) == kInf) return false;
  uint32_t cur = 0;
  for (;;) {
    const Node& n = nodes[cur];
    const uint32_t count = n.triangleCount();
    if (count > 0) {
      const Vec3* v = &m_triVerts[3 * size_t(n.offset)];
      for (uint32_t i = 0; i < count; ++i, v += 3) {
        float t, b1, b2;
        if (intersectTriangleWatertight(ray.origin, wr, v[0], v[1], v[2], ray.tMin, tMaxIn, t, b1, b2)) return true;
      }
    } else {
      const uint32_t l = cur + 1, r = n.offset;
      const float tl = enterNode(nodes[l], spheres, rb, ray.tMin, tMaxIn);
      const float tr = enterNode(nodes[r], spheres, rb, ray.tMin, tMaxIn);
      if (tl != kInf) {
        if (tr != kInf) stack[sp++] = tl <= tr ? r : l;
        cur = (tr != kInf && tr < tl) ? r : l;
        continue;
      }
      if (tr != kInf) {
        cur = r;
        continue;
      }
    }
    if (sp == 0) return false;
    cur = stack[--sp];
  }
}

}  // namespace voxcone

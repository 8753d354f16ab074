// How near a point is to a light: a hash grid of the lights' grown bounds, exact distances.

#include "voxcone/photon/light_proximity.h"

#include "voxcone/scene/scene.h"

#include <algorithm>
#include <cmath>

namespace voxcone {

namespace {
/// Cell entries the grid may hold: above it the cells grow (a lamp the size of the scene's
/// ground, grown by the radius, would otherwise fill millions of cells).
constexpr uint64_t kMaxEntries = uint64_t(1) << 22;
}  // namespace

Vec3 LightProximity::closestOnTriangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const float d1 = glm::dot(ab, ap), d2 = glm::dot(ac, ap);
  if (d1 <= 0.0f && d2 <= 0.0f) return a;
  const Vec3 bp = p - b;
  const float d3 = glm::dot(ab, bp), d4 = glm::dot(ac, bp);
  if (d3 >= 0.0f && d4 <= d3) return b;
  const float vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0f && d1 >= 0.0f && d3 <= 0.0f) return a + ab * (d1 / (d1 - d3));
  const Vec3 cp = p - c;
  const float d5 = glm::dot(ab, cp), d6 = glm::dot(ac, cp);
  if (d6 >= 0.0f && d5 <= d6) return c;
  const float vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0f && d2 >= 0.0f && d6 <= 0.0f) return a + ac * (d2 / (d2 - d6));
  const float va = d3 * d6 - d5 * d4;
  if (va <= 0.0f && d4 - d3 >= 0.0f && d5 - d6 >= 0.0f) return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
  const float denom = va + vb + vc;
  if (!(denom > 0.0f)) return a;  // degenerate: a point light, or a sliver
  return a + ab * (vb / denom) + ac * (vc / denom);
}

uint64_t LightProximity::key(int x, int y, int z) const {
  return (uint64_t(uint32_t(x) & 0x1fffffu) << 42) | (uint64_t(uint32_t(y) & 0x1fffffu) << 21) |
         uint64_t(uint32_t(z) & 0x1fffffu);
}

LightProximity::LightProximity(const Scene& scene, float radius) : m_radius(radius) {
  if (!(radius > 0.0f)) return;
  for (size_t t = 0; t < scene.triangles.size(); ++t) {
    if (!scene.materials[scene.triMaterial[t]].isEmissive()) continue;
    const UVec3& tri = scene.triangles[t];
    m_tris.push_back({scene.positions[tri.x], scene.positions[tri.y], scene.positions[tri.z]});
  }
  for (const PointLight& l : scene.pointLights) m_tris.push_back({l.position, l.position, l.position});
  if (m_tris.empty()) return;
  // Cells of the radius's size, larger where the lights would fill too many.
  m_cell = radius;
  for (;;) {
    uint64_t entries = 0;
    for (const Tri& t : m_tris) {
      const Vec3 lo = glm::min(t.a, glm::min(t.b, t.c)) - Vec3(radius), hi = glm::max(t.a, glm::max(t.b, t.c)) + Vec3(radius);
      const Vec3 n = glm::floor(hi / m_cell) - glm::floor(lo / m_cell) + Vec3(1.0f);
      entries += uint64_t(double(n.x) * double(n.y) * double(n.z));
    }
    if (entries <= kMaxEntries) break;
    m_cell *= 2.0f;
  }
  for (uint32_t i = 0; i < m_tris.size(); ++i) {
    const Tri& t = m_tris[i];
    const Vec3 lo = glm::floor((glm::min(t.a, glm::min(t.b, t.c)) - Vec3(radius)) / m_cell);
    const Vec3 hi = glm::floor((glm::max(t.a, glm::max(t.b, t.c)) + Vec3(radius)) / m_cell);
    for (int z = int(lo.z); z <= int(hi.z); ++z)
      for (int y = int(lo.y); y <= int(hi.y); ++y)
        for (int x = int(lo.x); x <= int(hi.x); ++x) m_cells[key(x, y, z)].push_back(i);
  }
}

float LightProximity::distance(const Vec3& p) const {
  if (m_tris.empty()) return kInf;
  const Vec3 c = glm::floor(p / m_cell);
  const auto it = m_cells.find(key(int(c.x), int(c.y), int(c.z)));
  if (it == m_cells.end()) return kInf;
  float best2 = m_radius * m_radius;
  for (const uint32_t i : it->second) {
    const Tri& t = m_tris[i];
    const Vec3 off = p - closestOnTriangle(p, t.a, t.b, t.c);
    best2 = std::min(best2, glm::dot(off, off));
  }
  return best2 < m_radius * m_radius ? std::sqrt(best2) : kInf;
}

}  // namespace voxcone

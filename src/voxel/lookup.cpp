/// \file lookup.cpp
/// The field's lookups: nearest, trilinear (blending two levels) and the cones' projected-area
/// lookup, and the caustic grid's radiance at a point.

#include "field_impl.h"

#include <algorithm>

namespace voxcone {

using namespace voxel;

namespace {

/// What a trilinear or nearest query accumulates.
struct Accum {
  double weight = 0.0;  ///< sum of filter weight * opacity
  double opacity = 0.0; ///< sum of filter weight * opacity (same, kept apart for clarity)
  DVec3 radiance{0.0};  ///< sum of filter weight * opacity * radiance
  DVec3 normal{0.0};    ///< sum of filter weight * opacity * normal
  DVec3 projected{0.0}; ///< sum of filter weight * opacity * |normal| per axis
  VoxelSample finish() const {
    VoxelSample s;
    s.opacity = float(opacity);
    s.projected = Vec3(projected);
    if (weight > 0.0) {
      s.radiance = Vec3(radiance / weight);
      s.normal = Vec3(normal / weight);
    }
    return s;
  }
};

/// Trilinear over the 8 voxel centres around worldPos (inactive voxels count as empty).
void trilinear(const Level& lv, const DVec3& origin, const Vec3& worldPos, double scale, Accum& acc) {
  const DVec3 q = (DVec3(worldPos) - origin) / lv.voxelSize - DVec3(0.5);
  const DVec3 base = glm::floor(q);
  const DVec3 f = q - base;
  IndexAccessor access(*lv.tree);
  for (int c = 0; c < 8; ++c) {
    const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
    const double w = (dx ? f.x : 1.0 - f.x) * (dy ? f.y : 1.0 - f.y) * (dz ? f.z : 1.0 - f.z) * scale;
    if (w <= 0.0) continue;
    VoxelRef r;
    if (!lv.find(int64_t(base.x) + dx, int64_t(base.y) + dy, int64_t(base.z) + dz, access, r)) continue;
    const double wo = w * lv.opacity(r.index);
    acc.weight += wo;
    acc.opacity += wo;
    acc.radiance += wo * DVec3(lv.radianceAt(r));
    acc.normal += wo * DVec3(lv.normalAt(r.index));
    acc.projected += wo * DVec3(lv.axisFractionAt(r.index));
  }
}

/// The cone's part of a trilinear lookup (VoxelField::coneSample), in float, normals decoded
/// only for their side (not normalized): the 8 corners' bricks are probed once each (most
/// lookups fall in one brick).
void coneTrilinear(const Level& lv, const Vec3& localPos, float scale, const Vec3& d, const Vec3& localApex,
                   float& density, Vec3& radiance) {
  const Vec3 absD = glm::abs(d);
  const Vec3 q = localPos * lv.invVoxelSize - Vec3(0.5f);
  const Vec3 base = glm::floor(q);
  const Vec3 f = q - base;
  const int32_t i0 = int32_t(base.x), j0 = int32_t(base.y), k0 = int32_t(base.z);
  const int32_t res = int32_t(lv.resolution);
  IndexAccessor access(*lv.tree);  // unused where the level has a flat brick table
  // Bricks of the corners: (i0 + d) >> 2 is i0 >> 2 or one more, per axis. -2: not probed yet.
  int64_t bricks[8] = {-2, -2, -2, -2, -2, -2, -2, -2};
  for (int c = 0; c < 8; ++c) {
    const int dx = c & 1, dy = (c >> 1) & 1, dz = (c >> 2) & 1;
    const float w = (dx ? f.x : 1.0f - f.x) * (dy ? f.y : 1.0f - f.y) * (dz ? f.z : 1.0f - f.z) * scale;
    if (w <= 0.0f) continue;
    const int32_t i = i0 + dx, j = j0 + dy, k = k0 + dz;
    if (i < 0 || j < 0 || k < 0 || i >= res || j >= res || k >= res) continue;
    const int slot = ((i >> 2) - (i0 >> 2)) | (((j >> 2) - (j0 >> 2)) << 1) | (((k >> 2) - (k0 >> 2)) << 2);
    int64_t& b = bricks[slot];
    if (b == -2) b = lv.brickAt(i >> 2, j >> 2, k >> 2, access);
    if (b < 0) continue;
    VoxelRef r;
    if (!lv.voxelIn(uint32_t(b), uint32_t(i), uint32_t(j), uint32_t(k), r)) continue;
    // Projected area along the cone's direction, and the radiance of the side the apex sees
    // (the direction from the apex, not the axis: a lookup's reach takes in surfaces beside
    // the axis, and a ray from the apex reaches them from their apex side).
    const Vec3 centre = (Vec3(float(i), float(j), float(k)) + Vec3(0.5f)) * lv.voxelSizeF;
    const ConeVoxel cv = lv.coneVoxel(r);
    const Vec3 proj = cv.projected * absD;
    const float area = w * (proj.x + proj.y + proj.z);
    density += area;
    radiance += area * (glm::dot(cv.side, centre - localApex) <= 0.0f ? cv.front : cv.back);
  }
}


}  // namespace

VoxelSample VoxelField::lookup(const Vec3& worldPos, int level) const {
  const Level* lv = m_impl->main.find(level);
  if (!lv) return {};
  const DVec3 q = glm::floor((DVec3(worldPos) - m_impl->origin) / lv->voxelSize);
  IndexAccessor access(*lv->tree);
  VoxelRef r;
  if (!lv->find(int64_t(q.x), int64_t(q.y), int64_t(q.z), access, r)) return {};
  VoxelSample s;
  s.opacity = lv->opacity(r.index);
  s.projected = s.opacity * lv->axisFractionAt(r.index);
  s.radiance = lv->radianceAt(r);
  s.normal = lv->normalAt(r.index);
  return s;
}

VoxelSample VoxelField::sample(const Vec3& worldPos, float level) const {
  const LevelStack& g = m_impl->main;
  if (g.empty()) return {};
  const float finest = float(g.levels.front().level), coarsest = float(g.levels.back().level);
  const float l = std::clamp(level, coarsest, finest);
  const int l0 = int(std::floor(l));
  const float t = l - float(l0);
  Accum acc;
  trilinear(*g.find(l0), m_impl->origin, worldPos, 1.0 - double(t), acc);
  if (t > 0.0f) trilinear(*g.find(l0 + 1), m_impl->origin, worldPos, double(t), acc);
  return acc.finish();
}

ConeSample VoxelField::coneSample(const Vec3& worldPos, float level, const Vec3& dir, const Vec3& apex) const {
  const LevelStack& g = m_impl->main;
  ConeSample out;
  if (g.empty()) return out;
  const float finest = float(g.levels.front().level), coarsest = float(g.levels.back().level);
  const float l = std::clamp(level, coarsest, finest);
  const int l0 = int(std::floor(l));
  const float t = l - float(l0);
  const Vec3 local = worldPos - m_impl->originF;
  const Vec3 localApex = apex - m_impl->originF;
  coneTrilinear(*g.find(l0), local, 1.0f - t, dir, localApex, out.density, out.radiance);
  if (t > 0.0f) coneTrilinear(*g.find(l0 + 1), local, t, dir, localApex, out.density, out.radiance);
  if (out.density > 0.0f) out.radiance /= out.density;
  return out;
}

Vec3 VoxelField::causticRadiance(const Vec3& worldPos, const Vec3& viewFrom) const {
  const LevelStack& g = m_impl->caustic;
  if (g.empty()) return Vec3(0.0f);
  // The projected-area-weighted mean of the faces seen from viewFrom: the surface's caustic
  // radiance on the viewer's side, not faded by the trilinear weights of empty voxels around it.
  float density = 0.0f;
  Vec3 radiance(0.0f);
  const Vec3 dir = glm::normalize(worldPos - viewFrom);
  coneTrilinear(g.levels.front(), worldPos - m_impl->originF, 1.0f, dir, viewFrom - m_impl->originF, density, radiance);
  return density > 0.0f ? radiance / density : Vec3(0.0f);
}

}  // namespace voxcone

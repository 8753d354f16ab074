/// \file estimate.cpp
/// What a field will take before it is built (VoxelField::estimate): per finest level, the
/// field's bytes and the peak while building, from a voxel count at a coarser level.

#include "field_common.h"
#include "voxelize.h"

#include "voxcone/scene/scene.h"
#include "voxcone/voxel/voxel_field.h"

#include <cstdio>

namespace voxcone {

using namespace voxel;

namespace {

/// The bytes a level of `voxels` voxels in `bricks` bricks takes (Level's layout, every voxel's
/// front lit, no back; the mips' axes and cone tables; the flat brick table up to level 8).
double levelBytes(int level, double voxels, double bricks, bool finest) {
  double bytes = voxels * (2.0 + 2.0 + 4.0)        // coverage, normal, front radiance
                 + bricks * (8.0 + 4.0 + 2 * 4.0)  // mask, base, the two sides' sparse bases
                 + bricks / 8.0 * 12.0;            // superbricks (a surface's fill a half of one's bricks)
  if (finest) bytes += bricks * 4.0;               // the diffuse fraction's sparse base
  else bytes += voxels * 3.0;                      // axes
  if (level <= kConeTableLevel) bytes += voxels * double(sizeof(ConeVoxel));
  if (level <= kDenseBrickLevel) bytes += std::pow(double(uint64_t(1) << level) / 4.0, 3.0) * 4.0;
  return bytes;
}

}  // namespace

std::string voxel::megabytes(uint64_t bytes) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.0f MB", double(bytes) / 1e6);
  return buf;
}

std::vector<FieldEstimate> VoxelField::estimate(const Scene& scene, const VoxelSettings& settings, bool quick,
                                                uint64_t budget) {
  DVec3 origin;
  double extent;
  fieldCube(scene, settings.padding, origin, extent);
  const int top = settings.level;
  // Per finest level m: its voxels V(m) and voxels per brick, from a count at level `probe`
  // (exact), growing by sqrt(voxels per brick) per level (4 on a surface: a brick of level
  // m + 2 is a voxel of level m).
  auto rowsFrom = [&](int probe, double voxels, double fill) {
    const double growth = std::sqrt(std::max(1.0, fill));
    std::vector<FieldEstimate> rows;
    for (int finest = settings.coarsestLevel; finest <= top; ++finest) {
      FieldEstimate e;
      e.level = finest;
      e.probeLevel = probe;
      double field = 0.0, finestVoxels = 0.0;
      for (int m = settings.coarsestLevel; m <= finest; ++m) {
        const double v = std::max(1.0, voxels * std::pow(growth, double(m - std::max(probe, 1))));
        if (m == finest) finestVoxels = v;
        field += levelBytes(m, v, std::max(1.0, v / std::max(1.0, fill)), m == finest);
      }
      e.voxels = uint64_t(finestVoxels);
      e.fieldBytes = uint64_t(field);
      // Held at once besides the field: one slab of voxelizeTriangles (48 bytes per overlap),
      // its work items (28 bytes per triangle, twice while they are cut into slabs), the
      // builder's arrays growing (coverage and normal copied as they double), injection's flux
      // (12 bytes per lit voxel).
      // A slab holds at most kRegionContributions overlaps, and about 3 per voxel (measured on
      // the dragon at level 10: 1.6 overlaps per voxel).
      const double slab = std::min(double(voxel::kRegionContributions), 3.0 * finestVoxels);
      const double transient = slab * 48.0 + 56.0 * double(scene.triangleCount()) + finestVoxels * (4.0 + 12.0);
      e.peakBytes = uint64_t(field + transient);
      rows.push_back(e);
    }
    return rows;
  };
  if (quick) {
    // The triangles' voxel boxes bound the finest level's voxels from above.
    const double bound = double(voxel::voxelBoxBound(scene, origin, extent / double(uint64_t(1) << top), uint32_t(1) << top));
    std::vector<FieldEstimate> rows = rowsFrom(top, bound, 16.0);
    for (FieldEstimate& r : rows) r.probeLevel = 0;
    if (rows.back().peakBytes <= budget) return rows;
  }
  const int probe = std::max(1, std::min(top - 2, 9));
  const double vs = extent / double(uint64_t(1) << probe);
  uint64_t voxels = 0, bricks = 0, lastBrick = ~uint64_t(0);
  voxel::voxelizeTriangles(scene, origin, vs, uint32_t(1) << probe, nullptr, [&](voxel::VoxelArrays& run) {
    voxels += run.size();
    for (uint64_t key : run.keys)
      if ((key >> 6) != lastBrick) {
        ++bricks;
        lastBrick = key >> 6;
      }
  });
  return rowsFrom(probe, double(voxels), double(voxels) / double(std::max<uint64_t>(1, bricks)));
}

}  // namespace voxcone

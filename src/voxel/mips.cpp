/// \file mips.cpp
/// The mips: each coarser level restricted from the next finer one (VoxelField::buildMips).

#include "level.h"

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>

namespace voxcone {
namespace voxel {

namespace {

/// 2x2x2 box restriction of `child` (parent (i, j, k) = child (i, j, k) >> 1), or the binomial
/// over 4x4x4 (MipFilter::Gaussian): opacity = weighted sum of child opacities; no diffuse
/// fraction (only injection reads it). Surfaces are two-sided, so each child is first turned
/// to agree with the most opaque child's normal (its front and back swapped when turned);
/// normal = opacity-weighted sum of the turned normals, renormalized; front and back radiance =
/// opacity-weighted means (sum(opacity * radiance) * voxel volume is preserved before storage).
/// For cones: axisFraction = opacity-weighted mean |normal| per axis.
/// The weight a child voxel gives one parent, per axis, in eighths: box 4 (its own parent
/// only, 4/8 per axis = 1/8 in 3D); Gaussian 3 to its own parent and 1 to the parent beside it
/// on its side (the binomial [1 3 3 1] / 8 over the 4 children nearest the parent's centre).
/// Either way a child's weights sum to 1/8 and a parent's to 1: coverage and flux are
/// conserved, and a plane stays one crossing (VoxelSample::projected) at every level.
struct ChildShare {
  uint64_t parent;
  VoxelRef child;
  float weight;
  bool operator<(const ChildShare& o) const {
    return parent != o.parent ? parent < o.parent : child.index < o.child.index;
  }
};

/// The shares of `child`'s voxel (i, j, k) in the parents of superbrick `ps` (packBrick), added
/// to `shares`.
void addShares(const VoxelRef& r, uint32_t i, uint32_t j, uint32_t k, uint32_t parentRes, MipFilter filter,
               uint64_t ps, std::vector<ChildShare>& shares) {
  const uint32_t c[3] = {i, j, k};
  if (filter == MipFilter::Box) {
    const uint64_t key = voxel::packKey(i >> 1, j >> 1, k >> 1);
    if ((key >> 12) == ps) shares.push_back({key, r, 0.125f});
    return;
  }
  uint32_t own[3], other[3];
  for (int a = 0; a < 3; ++a) {
    own[a] = c[a] >> 1;
    // An even child lies on its parent's low side, next to the parent below. At the
    // field's faces the neighbour does not exist: its share goes to the own parent.
    const int64_t n = (c[a] & 1u) ? int64_t(own[a]) + 1 : int64_t(own[a]) - 1;
    other[a] = n < 0 || n >= int64_t(parentRes) ? own[a] : uint32_t(n);
  }
  const size_t first = shares.size();
  for (int corner = 0; corner < 8; ++corner) {
    uint32_t q[3];
    float w = 1.0f;
    for (int a = 0; a < 3; ++a) {
      const bool side = (corner >> a) & 1;
      q[a] = side ? other[a] : own[a];
      w *= side ? 0.125f : 0.375f;
    }
    const uint64_t key = voxel::packKey(q[0], q[1], q[2]);
    if ((key >> 12) != ps) continue;
    // A child whose neighbour was folded back names its own parent twice: merge those.
    bool merged = false;
    for (size_t s = first; s < shares.size() && !merged; ++s)
      if (shares[s].parent == key) {
        shares[s].weight += w;
        merged = true;
      }
    if (!merged) shares.push_back({key, r, w});
  }
}

/// The parents of superbrick `ps` from sorted `shares` (one parent's run after another), appended to `out`.
void reduceShares(const Level& child, const std::vector<ChildShare>& shares, VoxelArrays& out) {
  const bool lit = child.lit;
  for (size_t a = 0; a < shares.size();) {
    size_t end = a;
    size_t ref = a;  // the child that weighs most: the others turn to agree with it
    for (; end < shares.size() && shares[end].parent == shares[a].parent; ++end)
      if (shares[end].weight * child.opacity(shares[end].child.index) >
          shares[ref].weight * child.opacity(shares[ref].child.index))
        ref = end;
    const Vec3 refNormal = child.normalAt(shares[ref].child.index);
    double opSum = 0.0;
    DVec3 front(0.0), back(0.0), nrm(0.0), axes(0.0);
    for (size_t b = a; b < end; ++b) {
      const VoxelRef& c = shares[b].child;
      const double op = double(shares[b].weight) * child.opacity(c.index);
      const Vec3 n = child.normalAt(c.index);
      const bool turned = glm::dot(n, refNormal) < 0.0f;
      opSum += op;
      nrm += op * DVec3(turned ? -n : n);
      axes += op * DVec3(child.axisFractionAt(c.index));
      if (lit) {
        const DVec3 f = DVec3(child.frontAt(c)), k = DVec3(child.backAt(c));
        front += op * (turned ? k : f);
        back += op * (turned ? f : k);
      }
    }
    const double len = glm::length(nrm);
    out.keys.push_back(shares[a].parent);
    out.coverage.push_back(float(opSum));
    out.axisFraction.push_back(opSum > 0.0 ? Vec3(axes / opSum) : Vec3(0.0f));
    out.normal.push_back(len > 0.0 ? Vec3(nrm / len) : refNormal);
    if (lit) {
      out.radiance.push_back(opSum > 0.0 ? Vec3(front / opSum) : Vec3(0.0f));
      out.radianceBack.push_back(opSum > 0.0 ? Vec3(back / opSum) : Vec3(0.0f));
    }
    a = end;
  }
}

}  // namespace

/// One coarser level from `child` (VoxelField::buildMips), a parent superbrick at a time: its
/// children lie in the 2^3 child superbricks below it (box) or the 4^3 around those (Gaussian);
/// each parent's shares are summed in child index order, so the level is the same at any
/// thread count. Parent superbricks go in parallel batches appended in key order.
Level restrictLevel(const Level& child, MipFilter filter, FieldQuantization* quant) {
  const uint32_t parentRes = std::max(1u, child.resolution >> 1);
  const int32_t childSupers = int32_t(std::max(1u, child.resolution >> voxel::kSuperLog2));
  // The parent superbricks with a child: those above each child superbrick (and beside, for
  // the Gaussian's reach across a superbrick's face), in key order.
  std::vector<uint64_t> parents;
  const int reach = filter == MipFilter::Box ? 0 : 1;
  const int32_t parentSupers = std::max(1, int32_t((parentRes + (1u << voxel::kSuperLog2) - 1) >> voxel::kSuperLog2));
  for (auto it = child.tree->cbeginValueOn(); it; ++it) {
    const openvdb::Coord c = it.getCoord();
    for (int dx = -reach; dx <= reach; ++dx)
      for (int dy = -reach; dy <= reach; ++dy)
        for (int dz = -reach; dz <= reach; ++dz) {
          const int32_t p[3] = {(c.x() >> 1) + dx, (c.y() >> 1) + dy, (c.z() >> 1) + dz};
          if (p[0] < 0 || p[1] < 0 || p[2] < 0 || p[0] >= parentSupers || p[1] >= parentSupers || p[2] >= parentSupers)
            continue;
          parents.push_back(voxel::packBrick(uint32_t(p[0]), uint32_t(p[1]), uint32_t(p[2])));
        }
  }
  tbb::parallel_sort(parents.begin(), parents.end());
  parents.erase(std::unique(parents.begin(), parents.end()), parents.end());

  LevelBuilder builder(child.level - 1, child.voxelSize * 2.0, quant);
  constexpr size_t kBatch = 256;
  std::vector<VoxelArrays> batch(kBatch);
  for (size_t first = 0; first < parents.size(); first += kBatch) {
    const size_t count = std::min(kBatch, parents.size() - first);
    tbb::parallel_for(size_t(0), count, [&](size_t n) {
      const uint64_t ps = parents[first + n];
      uint32_t p[3];
      voxel::unpackBrick(ps, p[0], p[1], p[2]);
      IndexAccessor acc(*child.tree);
      std::vector<ChildShare> shares;
      for (int32_t cx = 2 * int32_t(p[0]) - reach; cx <= 2 * int32_t(p[0]) + 1 + reach; ++cx)
        for (int32_t cy = 2 * int32_t(p[1]) - reach; cy <= 2 * int32_t(p[1]) + 1 + reach; ++cy)
          for (int32_t cz = 2 * int32_t(p[2]) - reach; cz <= 2 * int32_t(p[2]) + 1 + reach; ++cz) {
            if (cx < 0 || cy < 0 || cz < 0 || cx >= childSupers || cy >= childSupers || cz >= childSupers) continue;
            uint32_t s = 0;
            if (!acc.probeValue(openvdb::Coord(cx, cy, cz), s)) continue;
            child.forEachVoxelOf(s, uint32_t(cx), uint32_t(cy), uint32_t(cz),
                                 [&](const VoxelRef& r, uint32_t i, uint32_t j, uint32_t k) {
                                   addShares(r, i, j, k, parentRes, filter, ps, shares);
                                 });
          }
      std::sort(shares.begin(), shares.end());
      batch[n].clear();
      reduceShares(child, shares, batch[n]);
    });
    for (size_t n = 0; n < count; ++n) builder.append(batch[n]);
  }
  return builder.finish();
}


}  // namespace voxel
}  // namespace voxcone

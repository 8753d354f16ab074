/// \file voxelize.cpp
/// Surface voxelization: triangle/box overlap (Akenine-Möller 2001), the area of each
/// triangle inside each voxel (Sutherland-Hodgman clipping), merged deterministically by
/// sorting (voxel key, triangle) records.

#include "voxelize.h"

#include "voxcone/core/error.h"
#include "voxcone/scene/scene.h"

#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <atomic>
#include <cmath>

namespace voxcone::voxel {

namespace {

/// One triangle's area inside one voxel. (key, triangle) is unique, so sorting by it gives
/// one order, and one floating-point sum per voxel, whatever the thread count.
struct Contribution {
  uint64_t key;
  float areaVoxels;  ///< area / voxelSize^2
  uint32_t triangle;
};
static_assert(sizeof(Contribution) == 16, "keep the transient records at 16 bytes");

/// A triangle, or a slab of a large triangle's voxel range (so that a wall spanning a million
/// voxels is shared among threads).
struct WorkItem {
  uint32_t triangle;
  int32_t lo[3], hi[3];  ///< inclusive voxel range
  bool single;           ///< the whole triangle lies in one voxel
};

/// Triangles whose voxel range exceeds this many voxels are cut into slabs of about this size.
constexpr int64_t kSlabVoxels = 1 << 14;

/// Sutherland-Hodgman: keep the part of polygon `in` (n vertices) with sign * (p[axis] - bound) >= 0.
int clipAgainst(const DVec3* in, int n, DVec3* out, int axis, double bound, double sign) {
  int m = 0;
  for (int a = 0; a < n; ++a) {
    const DVec3& p = in[a];
    const DVec3& q = in[a + 1 == n ? 0 : a + 1];
    const double dp = sign * (p[axis] - bound);
    const double dq = sign * (q[axis] - bound);
    if (dp >= 0.0) out[m++] = p;
    if ((dp >= 0.0) != (dq >= 0.0)) out[m++] = p + (dp / (dp - dq)) * (q - p);
  }
  return m;
}

/// Voxel range of triangle `t` (inclusive, clamped to the grid): the floor of its index-space
/// bounds, so that a surface lying exactly on a voxel face belongs to the voxel above it only.
/// Returns the number of voxels in the range.
int64_t triangleVoxelRange(const Scene& scene, size_t t, const DVec3& origin, double invVoxel, int32_t maxIndex,
                           int32_t lo[3], int32_t hi[3]) {
  const UVec3& tv = scene.triangles[t];
  const DVec3 p[3] = {(DVec3(scene.positions[tv.x]) - origin) * invVoxel, (DVec3(scene.positions[tv.y]) - origin) * invVoxel,
                      (DVec3(scene.positions[tv.z]) - origin) * invVoxel};
  int64_t count = 1;
  for (int a = 0; a < 3; ++a) {
    const double mn = std::min(p[0][a], std::min(p[1][a], p[2][a])), mx = std::max(p[0][a], std::max(p[1][a], p[2][a]));
    lo[a] = std::clamp(int32_t(std::floor(mn)), 0, maxIndex);
    hi[a] = std::clamp(int32_t(std::floor(mx)), 0, maxIndex);
    count *= int64_t(hi[a] - lo[a] + 1);
  }
  return count;
}

}  // namespace

bool triangleBoxOverlap(const DVec3& center, double h, const DVec3 tri[3]) {
  const DVec3 v0 = tri[0] - center, v1 = tri[1] - center, v2 = tri[2] - center;
  const DVec3 e[3] = {v1 - v0, v2 - v1, v0 - v2};
  // The 9 axes cross(edge, box axis).
  for (int a = 0; a < 3; ++a) {
    const DVec3& ed = e[a];
    const DVec3 axes[3] = {DVec3(0.0, ed.z, -ed.y), DVec3(-ed.z, 0.0, ed.x), DVec3(ed.y, -ed.x, 0.0)};
    for (const DVec3& ax : axes) {
      const double p0 = glm::dot(ax, v0), p1 = glm::dot(ax, v1), p2 = glm::dot(ax, v2);
      const double mn = std::min(p0, std::min(p1, p2)), mx = std::max(p0, std::max(p1, p2));
      const double rad = h * (std::abs(ax.x) + std::abs(ax.y) + std::abs(ax.z));
      if (mn > rad || mx < -rad) return false;
    }
  }
  // The 3 box face normals: the triangle's bounds against the box.
  for (int a = 0; a < 3; ++a) {
    const double mn = std::min(v0[a], std::min(v1[a], v2[a])), mx = std::max(v0[a], std::max(v1[a], v2[a]));
    if (mn > h || mx < -h) return false;
  }
  // The triangle's plane against the box: |n . v0| <= projected box radius.
  const DVec3 n = glm::cross(e[0], e[1]);
  const double r = h * (std::abs(n.x) + std::abs(n.y) + std::abs(n.z));
  return std::abs(glm::dot(n, v0)) <= r;
}

double clippedTriangleArea(const DVec3 tri[3], const DVec3& lo) {
  // 3 vertices plus at most one more per clipping plane.
  DVec3 bufA[12], bufB[12];
  bufA[0] = tri[0];
  bufA[1] = tri[1];
  bufA[2] = tri[2];
  int n = 3;
  DVec3* in = bufA;
  DVec3* out = bufB;
  for (int axis = 0; axis < 3 && n >= 3; ++axis) {
    n = clipAgainst(in, n, out, axis, lo[axis], 1.0);
    std::swap(in, out);
    if (n < 3) break;
    n = clipAgainst(in, n, out, axis, lo[axis] + 1.0, -1.0);
    std::swap(in, out);
  }
  if (n < 3) return 0.0;
  // Polygon area: half the length of the summed fan cross products.
  DVec3 sum(0.0);
  for (int a = 1; a + 1 < n; ++a) sum += glm::cross(in[a] - in[0], in[a + 1] - in[0]);
  return 0.5 * glm::length(sum);
}

uint64_t voxelBoxBound(const Scene& scene, const DVec3& origin, double voxelSize, uint32_t resolution) {
  const double invVoxel = 1.0 / voxelSize;
  const int32_t maxIndex = int32_t(resolution) - 1;
  return tbb::parallel_reduce(
      tbb::blocked_range<size_t>(0, scene.triangleCount(), 16384), uint64_t(0),
      [&](const tbb::blocked_range<size_t>& r, uint64_t sum) {
        int32_t lo[3], hi[3];
        for (size_t t = r.begin(); t != r.end(); ++t)
          if (!scene.materials[scene.triMaterial[t]].isClearGlass())
            sum += uint64_t(triangleVoxelRange(scene, t, origin, invVoxel, maxIndex, lo, hi));
        return sum;
      },
      std::plus<uint64_t>());
}

namespace {

/// The bricks a voxelization is limited to (VoxelSink's `onlyBricks`: the caustic grid's), or
/// none: every voxel passes.
class BrickFilter {
public:
  BrickFilter(const std::vector<uint64_t>* onlyBricks, int32_t maxIndex) : m_bricks(onlyBricks) {
    for (int a = 0; a < 3; ++a) {
      m_lo[a] = 0;
      m_hi[a] = maxIndex;
    }
    if (!onlyBricks) return;
    // The listed bricks' bounds, in voxels: most triangles miss them (caustics are local).
    for (int a = 0; a < 3; ++a) {
      m_lo[a] = maxIndex;
      m_hi[a] = onlyBricks->empty() ? -1 : 0;
    }
    for (uint64_t b : *onlyBricks) {
      uint32_t c[3];
      unpackBrick(b, c[0], c[1], c[2]);
      for (int a = 0; a < 3; ++a) {
        m_lo[a] = std::min(m_lo[a], int32_t(c[a] << kBrickLog2));
        m_hi[a] = std::max(m_hi[a], int32_t(c[a] << kBrickLog2) + (1 << kBrickLog2) - 1);
      }
    }
  }
  bool all() const { return !m_bricks; }
  /// Whether voxel (i, j, k) lies in a listed brick (with a list).
  bool listed(int32_t i, int32_t j, int32_t k) const {
    return std::binary_search(m_bricks->begin(), m_bricks->end(),
                              packBrick(uint32_t(i) >> kBrickLog2, uint32_t(j) >> kBrickLog2, uint32_t(k) >> kBrickLog2));
  }
  /// Whether a voxel range reaches a listed brick (always, without a list).
  bool reaches(const int32_t lo[3], const int32_t hi[3]) const {
    if (!m_bricks) return true;
    for (int a = 0; a < 3; ++a)
      if (hi[a] < m_lo[a] || lo[a] > m_hi[a]) return false;
    for (int32_t bi = lo[0] >> kBrickLog2; bi <= hi[0] >> kBrickLog2; ++bi)
      for (int32_t bj = lo[1] >> kBrickLog2; bj <= hi[1] >> kBrickLog2; ++bj)
        for (int32_t bk = lo[2] >> kBrickLog2; bk <= hi[2] >> kBrickLog2; ++bk)
          if (listed(bi << kBrickLog2, bj << kBrickLog2, bk << kBrickLog2)) return true;
    return false;
  }

private:
  const std::vector<uint64_t>* m_bricks;
  int32_t m_lo[3], m_hi[3];  ///< the listed bricks' bounds, in voxels
};

/// The work items of every triangle in the field (smooth glass is not: cones see through it) that
/// reaches the filter's bricks: its voxel range, cut into slabs of about kSlabVoxels voxels along
/// its longest axis where larger. Fixed chunks of triangles in parallel, joined in chunk order:
/// the items are in triangle order at any thread count (voxelizing the dragon at level 5, 2
/// threads: 95 -> 88 ms).
std::vector<WorkItem> workItems(const Scene& scene, const DVec3& origin, double invVoxel, int32_t maxIndex,
                                const BrickFilter& filter) {
  const size_t triCount = scene.triangleCount();
  constexpr size_t kItemChunk = 16384;
  std::vector<std::vector<WorkItem>> chunkItems((triCount + kItemChunk - 1) / kItemChunk);
  tbb::parallel_for(size_t(0), chunkItems.size(), [&](size_t chunk) {
    std::vector<WorkItem>& local = chunkItems[chunk];
    const size_t end = std::min(triCount, (chunk + 1) * kItemChunk);
    for (size_t t = chunk * kItemChunk; t < end; ++t) {
      if (scene.materials[scene.triMaterial[t]].isClearGlass()) continue;
      WorkItem item{uint32_t(t), {0, 0, 0}, {0, 0, 0}, false};
      const int64_t count = triangleVoxelRange(scene, t, origin, invVoxel, maxIndex, item.lo, item.hi);
      if (!filter.reaches(item.lo, item.hi)) continue;
      item.single = count == 1;
      if (count <= kSlabVoxels) {
        local.push_back(item);
        continue;
      }
      int axis = 0;
      for (int a = 1; a < 3; ++a)
        if (item.hi[a] - item.lo[a] > item.hi[axis] - item.lo[axis]) axis = a;
      const int64_t rows = item.hi[axis] - item.lo[axis] + 1;
      const int64_t perRow = count / rows;
      const int32_t rowsPerSlab = int32_t(std::max<int64_t>(1, kSlabVoxels / perRow));
      for (int32_t r = item.lo[axis]; r <= item.hi[axis]; r += rowsPerSlab) {
        WorkItem slab = item;
        slab.lo[axis] = r;
        slab.hi[axis] = std::min(item.hi[axis], r + rowsPerSlab - 1);
        local.push_back(slab);
      }
    }
  });
  size_t itemCount = 0;
  for (const auto& c : chunkItems) itemCount += c.size();
  std::vector<WorkItem> items;
  items.reserve(itemCount);
  for (auto& c : chunkItems) {
    items.insert(items.end(), c.begin(), c.end());
    std::vector<WorkItem>().swap(c);
  }
  return items;
}

/// The items (emptied) shared among slabs of whole superbrick columns along x (the key's leading
/// coordinate, so each slab's voxels follow the previous slab's in key order), cut where the
/// overlaps the items' voxel boxes could hold (spread evenly over each box's x range) pass
/// kRegionContributions: each slab's items in item (triangle) order, their x range cut to it.
std::vector<std::vector<WorkItem>> slabsOf(std::vector<WorkItem>& items, uint32_t resolution) {
  const int32_t superSide = int32_t(1) << kSuperLog2;
  const int32_t columns = std::max<int32_t>(1, (int32_t(resolution) + superSide - 1) / superSide);
  std::vector<double> perColumn(size_t(columns) + 1, 0.0);
  {
    std::vector<double> rate(size_t(resolution) + 1, 0.0);  // difference array over voxel x
    for (const WorkItem& item : items) {
      const double volume = double(item.hi[0] - item.lo[0] + 1) * double(item.hi[1] - item.lo[1] + 1) *
                            double(item.hi[2] - item.lo[2] + 1);
      const double r = volume / double(item.hi[0] - item.lo[0] + 1);
      rate[size_t(item.lo[0])] += r;
      rate[size_t(item.hi[0]) + 1] -= r;
    }
    double running = 0.0;
    for (int32_t x = 0; x < int32_t(resolution); ++x) {
      running += rate[size_t(x)];
      perColumn[size_t(x / superSide)] += running;
    }
  }
  std::vector<int32_t> cuts{0};  // voxel x where each slab begins
  {
    double sum = 0.0;
    for (int32_t c = 0; c < columns; ++c) {
      if (sum > 0.0 && sum + perColumn[size_t(c)] > double(kRegionContributions)) {
        cuts.push_back(c * superSide);
        sum = 0.0;
      }
      sum += perColumn[size_t(c)];
    }
    cuts.push_back(std::max(int32_t(resolution), columns * superSide));
  }
  const size_t regions = cuts.size() - 1;
  std::vector<std::vector<WorkItem>> regionItems(regions);
  if (regions == 1) {
    regionItems[0].swap(items);
    return regionItems;
  }
  auto regionOf = [&](int32_t x) { return size_t(std::upper_bound(cuts.begin(), cuts.end(), x) - cuts.begin()) - 1; };
  std::vector<size_t> counts(regions, 0);
  for (const WorkItem& item : items)
    for (size_t r = regionOf(item.lo[0]); r < regions && cuts[r] <= item.hi[0]; ++r) ++counts[r];
  for (size_t r = 0; r < regions; ++r) regionItems[r].reserve(counts[r]);
  for (const WorkItem& item : items)
    for (size_t r = regionOf(item.lo[0]); r < regions && cuts[r] <= item.hi[0]; ++r) {
      WorkItem cut = item;
      cut.lo[0] = std::max(item.lo[0], cuts[r]);
      cut.hi[0] = std::min(item.hi[0], cuts[r + 1] - 1);
      regionItems[r].push_back(cut);
    }
  std::vector<WorkItem>().swap(items);
  return regionItems;
}

/// Every (voxel, triangle) overlap of a slab's items with its clipped area, per fixed chunk of
/// items, the chunks concatenated in order: listed by triangle. Throws CancelledError when the
/// progress asks.
std::vector<Contribution> overlapsOf(const Scene& scene, const std::vector<WorkItem>& slab, const DVec3& origin,
                                     double invVoxel, const BrickFilter& filter, Progress* progress) {
  auto indexPos = [&](uint32_t vertex) { return (DVec3(scene.positions[vertex]) - origin) * invVoxel; };
  std::atomic<bool> cancelled{false};
  constexpr size_t kChunk = 1024;
  std::vector<std::vector<Contribution>> chunks((slab.size() + kChunk - 1) / kChunk);
  tbb::parallel_for(size_t(0), chunks.size(), [&](size_t chunk) {
    if (cancelled.load(std::memory_order_relaxed)) return;
    if (progress && progress->cancelled()) {
      cancelled = true;
      return;
    }
    const size_t begin = chunk * kChunk, end = std::min(slab.size(), (chunk + 1) * kChunk);
    std::vector<Contribution>& local = chunks[chunk];
    for (size_t w = begin; w != end; ++w) {
      const WorkItem& item = slab[w];
      const UVec3& tv = scene.triangles[item.triangle];
      const DVec3 tri[3] = {indexPos(tv.x), indexPos(tv.y), indexPos(tv.z)};
      if (item.single) {
        if (!filter.all() && !filter.listed(item.lo[0], item.lo[1], item.lo[2])) continue;
        // Inside one voxel (most of a fine mesh's triangles at the default level): the overlap
        // test passes and clipping keeps all three vertices, so the clipped area is the
        // triangle's own, the same formula on the same vertices (bit-identical, measured: the
        // same field on the dragon), without the 13 axis tests and 6 clipping passes.
        const double area = 0.5 * glm::length(glm::cross(tri[1] - tri[0], tri[2] - tri[0]));
        if (area > 0.0)
          local.push_back({packKey(uint32_t(item.lo[0]), uint32_t(item.lo[1]), uint32_t(item.lo[2])), float(area),
                           item.triangle});
        continue;
      }
      for (int32_t i = item.lo[0]; i <= item.hi[0]; ++i)
        for (int32_t j = item.lo[1]; j <= item.hi[1]; ++j)
          for (int32_t k = item.lo[2]; k <= item.hi[2]; ++k) {
            if (!filter.all() && !filter.listed(i, j, k)) continue;
            const DVec3 lo(i, j, k);
            if (!triangleBoxOverlap(lo + DVec3(0.5), 0.5, tri)) continue;
            const double area = clippedTriangleArea(tri, lo);
            // Touching (zero-area) overlaps hold no surface: the voxel stays inactive.
            if (!(area > 0.0)) continue;
            local.push_back({packKey(uint32_t(i), uint32_t(j), uint32_t(k)), float(area), item.triangle});
          }
    }
    if (progress) progress->advance(end - begin);
  });
  if (cancelled) throw CancelledError();
  std::vector<Contribution> all;
  size_t total = 0;
  for (const auto& v : chunks) total += v.size();
  all.reserve(total);
  for (auto& v : chunks) {
    all.insert(all.end(), v.begin(), v.end());
    std::vector<Contribution>().swap(v);
  }
  return all;
}

/// `all` sorted by (key, triangle): a stable LSD radix sort on the key compacted to the level's
/// bits (superbrick coordinates of log2(resolution) - 4 bits, then the 12 bits of brick and
/// voxel, ordered as the packed key) keeps the triangle order within each key (std::sort on
/// (key, triangle) was 8% of a dragon render at level 6, more than the voxelization itself).
void sortByVoxel(std::vector<Contribution>& all, uint32_t resolution) {
  const int superBits = std::max(0, int(std::log2(double(resolution)) + 0.5) - kSuperLog2);
  const auto compact = [&](uint64_t key) {
    uint32_t si, sj, sk;
    unpackBrick(key >> 12, si, sj, sk);
    return ((((uint64_t(si) << superBits) | sj) << superBits | sk) << 12) | (key & 4095u);
  };
  const int keyBits = 3 * superBits + 12;
  constexpr int kDigit = 11;
  std::vector<uint64_t> keys(all.size()), keysTmp(all.size());
  for (size_t a = 0; a < all.size(); ++a) keys[a] = compact(all[a].key);
  std::vector<Contribution> tmp(all.size());
  std::vector<size_t> count(size_t(1) << kDigit);
  for (int shift = 0; shift < keyBits; shift += kDigit) {
    std::fill(count.begin(), count.end(), size_t(0));
    const uint64_t mask = (uint64_t(1) << kDigit) - 1;
    for (uint64_t k : keys) ++count[(k >> shift) & mask];
    size_t sum = 0;
    for (size_t& c : count) {
      const size_t n = c;
      c = sum;
      sum += n;
    }
    for (size_t a = 0; a < all.size(); ++a) {
      const size_t at = count[(keys[a] >> shift) & mask]++;
      tmp[at] = all[a];
      keysTmp[at] = keys[a];
    }
    all.swap(tmp);
    keys.swap(keysTmp);
  }
}

/// The voxels of sorted contributions into `out`: each voxel's run reduced in (triangle) order;
/// runs in parallel, each into its own slot.
void reduceVoxels(const Scene& scene, const std::vector<Contribution>& all, VoxelArrays& out) {
  // Geometric normal per triangle, looked up, not stored per record.
  auto triNormal = [&](uint32_t t) {
    const UVec3& tv = scene.triangles[t];
    const DVec3 p0(scene.positions[tv.x]), p1(scene.positions[tv.y]), p2(scene.positions[tv.z]);
    const DVec3 n = glm::cross(p1 - p0, p2 - p0);
    const double len = glm::length(n);
    return len > 0.0 ? n / len : DVec3(0.0, 0.0, 1.0);
  };
  std::vector<size_t> runStart;
  for (size_t a = 0; a < all.size(); ++a)
    if (a == 0 || all[a].key != all[a - 1].key) runStart.push_back(a);
  runStart.push_back(all.size());
  const size_t voxels = runStart.size() - 1;
  out.clear();
  out.keys.resize(voxels);
  out.coverage.resize(voxels);
  out.normal.resize(voxels);
  out.diffuse.resize(voxels);
  tbb::parallel_for(size_t(0), voxels, [&](size_t r) {
    const size_t a = runStart[r], end = runStart[r + 1];
    double area = 0.0, diffuseArea = 0.0;
    DVec3 normal(0.0);
    // Surfaces are two-sided: each triangle's normal is flipped into the hemisphere of the
    // voxel's first (lowest-index) triangle so that the two sides of a thin sheet add up
    // instead of cancelling; the sign follows that triangle's winding.
    const DVec3 reference = triNormal(all[a].triangle);
    for (size_t b = a; b < end; ++b) {
      const double w = all[b].areaVoxels;
      const DVec3 n = b == a ? reference : triNormal(all[b].triangle);
      area += w;
      normal += (glm::dot(n, reference) < 0.0 ? -w : w) * n;
      // Specular-only surfaces add area (opacity) but gather no diffuse light.
      if (scene.materials[scene.triMaterial[all[b].triangle]].hasDiffuseBase()) diffuseArea += w;
    }
    const double len = glm::length(normal);
    out.keys[r] = all[a].key;
    out.coverage[r] = float(area);
    out.normal[r] = Vec3(len > 0.0 ? normal / len : reference);
    out.diffuse[r] = float(diffuseArea / area);
  });
}

}  // namespace

size_t voxelizeTriangles(const Scene& scene, const DVec3& origin, double voxelSize, uint32_t resolution,
                         Progress* progress, const VoxelSink& sink, const std::vector<uint64_t>* onlyBricks) {
  const double invVoxel = 1.0 / voxelSize;
  const int32_t maxIndex = int32_t(resolution) - 1;
  const BrickFilter filter(onlyBricks, maxIndex);
  // Voxel range of every triangle: floor of its index-space bounds, so that a surface lying
  // exactly on a voxel face belongs to the voxel above it only (no double-counted area).
  std::vector<WorkItem> items = workItems(scene, origin, invVoxel, maxIndex, filter);
  const size_t itemCount = items.size();
  std::vector<std::vector<WorkItem>> slabs = slabsOf(items, resolution);

  if (progress) progress->start("voxelize", itemCount);
  VoxelArrays out;
  for (std::vector<WorkItem>& slab : slabs) {
    std::vector<Contribution> all = overlapsOf(scene, slab, origin, invVoxel, filter, progress);
    std::vector<WorkItem>().swap(slab);
    sortByVoxel(all, resolution);
    reduceVoxels(scene, all, out);
    std::vector<Contribution>().swap(all);
    sink(out);
  }
  if (progress) progress->finish();
  return slabs.size();
}

}  // namespace voxcone::voxel

/// \file inject.cpp
/// Photons into the field: each photon's reflected flux splatted over the voxels of the surface
/// it landed on, on the side it arrived from, then turned into radiance (VoxelField::inject).

#include "field_impl.h"

#include "voxcone/core/error.h"
#include "voxcone/core/timer.h"

#include <tbb/parallel_for.h>

#include <algorithm>

namespace voxcone {

using namespace voxel;

namespace {

/// Reflected flux (photon power times the albedo it landed on) per voxel and side (front: the
/// side the voxel's normal points to), only for the bricks some photon reached on that side (a
/// few thousand photons reach a fraction of a fine level's bricks).
struct SidedFlux {
  SparseBricks<Vec3> side[2];
};

/// The footprint spreads a photon over the surface it landed on: a voxel whose mean normal
/// turns more than 60 degrees from the photon's belongs to another surface across a crease (a
/// wall beside a lit floor), not to this one; a corner voxel's 45 degrees still counts.
constexpr float kSameSurfaceCos = 0.5f;

/// Splat `photons` into `lv` (see VoxelField::inject); returns the reflected flux per voxel and
/// side, and adds the power that landed to `injected`, that found no voxel to `dropped`.
SidedFlux splatPhotons(const Level& lv, const DVec3& origin, const PhotonList& photons, float sigmaVoxels,
                       DVec3& injected, DVec3& dropped, Progress* progress) {
  SidedFlux flux;
  for (SparseBricks<Vec3>& f : flux.side) f.base.assign(lv.brickMask.size(), SparseBricks<Vec3>::kNone);
  const double radius = 3.0 * double(sigmaVoxels);
  const double inv2s2 = 1.0 / (2.0 * double(sigmaVoxels) * sigmaVoxels);
  // Photons go in fixed blocks; a wave of blocks is splatted in parallel into per-block lists,
  // then added in block order, so the float sums are the same at any thread count.
  constexpr size_t kBlock = 2048, kWave = 64;
  const size_t blocks = (photons.size() + kBlock - 1) / kBlock;
  struct Splat {
    uint32_t brick;
    uint8_t rank;
    bool back;
    Vec3 flux;
  };
  std::vector<std::vector<Splat>> lists(std::min(blocks, kWave));
  std::vector<DVec3> blockLanded(lists.size()), blockDropped(lists.size());
  for (size_t wave = 0; wave < blocks; wave += kWave) {
    if (progress && progress->cancelled()) throw CancelledError();
    const size_t waveBlocks = std::min(kWave, blocks - wave);
    tbb::parallel_for(size_t(0), waveBlocks, [&](size_t wb) {
      std::vector<Splat>& out = lists[wb];
      out.clear();
      blockLanded[wb] = blockDropped[wb] = DVec3(0.0);
      IndexAccessor access(*lv.tree);
      struct Candidate {
        VoxelRef voxel;
        float weight;
      };
      // Voxels whose (wound) normal faces the photon, and those facing away from it.
      std::vector<Candidate> cand[2];
      std::vector<double> gauss[3];
      const size_t begin = (wave + wb) * kBlock, end = std::min(photons.size(), begin + kBlock);
      for (size_t p = begin; p < end; ++p) {
        const Photon& ph = photons[p];
        const Vec3 reflected = ph.power * ph.albedo;
        const DVec3 q = (DVec3(ph.position) - origin) / lv.voxelSize;
        cand[0].clear();
        cand[1].clear();
        double wsum[2] = {0.0, 0.0};
        int64_t lo[3], hi[3];
        for (int a = 0; a < 3; ++a) {
          lo[a] = int64_t(std::ceil(q[a] - 0.5 - radius));
          hi[a] = int64_t(std::floor(q[a] - 0.5 + radius));
          // The Gaussian is separable: one exp per voxel row instead of one per voxel.
          gauss[a].clear();
          for (int64_t i = lo[a]; i <= hi[a]; ++i) gauss[a].push_back(std::exp(-sqr(double(i) + 0.5 - q[a]) * inv2s2));
        }
        for (int64_t i = lo[0]; i <= hi[0]; ++i)
          for (int64_t j = lo[1]; j <= hi[1]; ++j)
            for (int64_t k = lo[2]; k <= hi[2]; ++k) {
              const double d2 = sqr(double(i) + 0.5 - q.x) + sqr(double(j) + 0.5 - q.y) + sqr(double(k) + 0.5 - q.z);
              if (d2 > radius * radius) continue;
              VoxelRef r;
              if (!lv.find(i, j, k, access, r)) continue;
              // Only diffuse surface gathers light.
              const float diffuse = lv.diffuseAt(r);
              if (!(diffuse > 0.0f)) continue;
              // Voxels of another surface (kSameSurfaceCos) take none of the photon.
              const Vec3 n = decodeNormalDirection(lv.normal[r.index]);
              const float cosNormals = glm::dot(n, ph.normal);
              if (sqr(cosNormals) <= sqr(kSameSurfaceCos) * glm::dot(n, n)) continue;
              // Gaussian footprint times the diffuse surface area the voxel holds: a uniform
              // photon density then gives a uniform irradiance flux / area, where the plain
              // Gaussian would give a voxel clipped to a sliver of surface the flux of a full
              // voxel (and radiance up to 1 / sliver area).
              const double g = gauss[0][size_t(i - lo[0])] * gauss[1][size_t(j - lo[1])] * gauss[2][size_t(k - lo[2])];
              const double w = g * double(lv.coverage[r.index]) * double(diffuse);
              const int back = cosNormals < 0.0f;
              cand[back].push_back({r, float(w)});
              wsum[back] += w;
            }
        // The photon lands on the side it arrived on: the front of the voxels that face it (a
        // closed object's far face, in the next voxel layer, stays dark inside), or, where none
        // does, the back of those facing away (an open panel lit from behind its winding).
        // Normalized over the chosen voxels: the photon's power is conserved.
        const int side = wsum[0] > 0.0 ? 0 : 1;
        if (wsum[side] > 0.0) {
          for (const Candidate& c : cand[side])
            out.push_back({c.voxel.brick, uint8_t(c.voxel.rank), side == 1, reflected * float(double(c.weight) / wsum[side])});
          blockLanded[wb] += DVec3(ph.power);
          continue;
        }
        VoxelRef r;
        if (lv.find(int64_t(std::floor(q.x)), int64_t(std::floor(q.y)), int64_t(std::floor(q.z)), access, r)) {
          out.push_back({r.brick, uint8_t(r.rank),
                         glm::dot(decodeNormalDirection(lv.normal[r.index]), ph.normal) < 0.0f, reflected});
          blockLanded[wb] += DVec3(ph.power);
        } else {
          blockDropped[wb] += DVec3(ph.power);
        }
      }
    });
    for (size_t wb = 0; wb < waveBlocks; ++wb) {
      for (const Splat& s : lists[wb]) {
        SparseBricks<Vec3>& f = flux.side[s.back];
        uint32_t& base = f.base[s.brick];
        if (base == SparseBricks<Vec3>::kNone) {
          base = uint32_t(f.values.size());
          f.values.resize(f.values.size() + size_t(__builtin_popcountll(lv.brickMask[s.brick])), Vec3(0.0f));
        }
        f.values[size_t(base) + s.rank] += s.flux;
      }
      injected += blockLanded[wb];
      dropped += blockDropped[wb];
    }
    if (progress) progress->advance(std::min(photons.size(), (wave + waveBlocks) * kBlock) - wave * kBlock);
  }
  return flux;
}

}  // namespace

namespace voxel {

Level keepLit(const Level& lv) {
  struct Lit {
    uint64_t key;
    VoxelRef ref;
    bool operator<(const Lit& o) const { return key < o.key; }
  };
  std::vector<Lit> lit;
  lv.forEachVoxel([&](const VoxelRef& r, uint32_t i, uint32_t j, uint32_t k) {
    if (!isBlack(lv.radianceAt(r))) lit.push_back({voxel::packKey(i, j, k), r});
  });
  std::sort(lit.begin(), lit.end());
  VoxelArrays a;
  for (const Lit& l : lit) {
    a.keys.push_back(l.key);
    a.coverage.push_back(float(lv.coverage[l.ref.index]));
    a.normal.push_back(lv.normalAt(l.ref.index));
    a.diffuse.push_back(lv.diffuseAt(l.ref));
    a.radiance.push_back(lv.frontAt(l.ref));
    a.radianceBack.push_back(lv.backAt(l.ref));
  }
  LevelBuilder builder(lv.level, lv.voxelSize);
  builder.append(a);
  Level out = builder.finish();
  out.buildSeconds = lv.buildSeconds;
  return out;
}

}  // namespace

void VoxelField::Impl::inject(LevelStack& grid, const PhotonList& photons, Progress* progress, DVec3& injectedOut) {
  if (grid.empty()) return;
  Timer timer;
  Level& lv = grid.levels.front();
  injectedOut = DVec3(0.0);
  SidedFlux flux = splatPhotons(lv, origin, photons, settings.kernelSigmaVoxels, injectedOut, dropped, progress);
  // L = Phi_r / (pi A) per side, Phi_r the reflected flux (albedo times the power that landed),
  // A = coverage * voxelSize^2 the voxel's whole surface (each side of a two-sided surface has
  // all of it): the mean over the voxel's surface of the diffuse part's albedo / pi * E.
  const double voxelArea = lv.voxelSize * lv.voxelSize;
  const auto radianceOf = [&](const SparseBricks<Vec3>& f, uint32_t brick, uint32_t rank) {
    const double area = double(lv.coverage[size_t(lv.brickBase[brick]) + rank]) * voxelArea;
    return area > 0.0 ? Vec3(DVec3(f.values[size_t(f.base[brick]) + rank]) * (1.0 / (kPiD * area))) : Vec3(0.0f);
  };
  lv.coneTable.clear();  // stale until buildConeTable runs again
  // Each side in the flux's own sparse layout, the bricks no photon reached left out.
  for (int side = 0; side < 2; ++side) {
    SparseBricks<Vec3>& f = flux.side[side];
    SparseBricks<uint32_t>& out = lv.radiance[side];
    out = SparseBricks<uint32_t>();
    if (!f.values.empty()) {
      out.base = f.base;
      out.values.resize(f.values.size());
      tbb::parallel_for(uint32_t(0), uint32_t(lv.brickMask.size()), [&](uint32_t b) {
        if (f.base[b] == SparseBricks<Vec3>::kNone) return;
        const uint32_t n = uint32_t(__builtin_popcountll(lv.brickMask[b]));
        for (uint32_t r = 0; r < n; ++r) out.values[size_t(f.base[b]) + r] = encodeRgb9e5(radianceOf(f, b, r));
      });
    }
    if (FieldQuantization* q = &grid == &main ? quantPtr() : nullptr)
      for (uint32_t b = 0; b < lv.brickMask.size() && !f.values.empty(); ++b) {
        if (f.base[b] == SparseBricks<Vec3>::kNone) continue;
        for (uint32_t r = 0; r < uint32_t(__builtin_popcountll(lv.brickMask[b])); ++r)
          q->addRadiance(radianceOf(f, b, r), out.values[size_t(f.base[b]) + r]);
      }
    f = SparseBricks<Vec3>();
  }
  lv.lit = true;
  // Mips built before are stale: dropped, buildMips makes them anew (rebuilding them here too
  // built every mip twice per pass of a progressive render).
  grid.levels.resize(1);
  grid.injectSeconds = timer.seconds();
}

}  // namespace voxcone

/// \file voxel_field.cpp
/// The sparse voxel field (VoxelField): voxelizing a scene into its finest level, injecting
/// photons, building the mips, and what the field reports of itself. The layout of a level is
/// in level.h; the jobs have their own files: level.cpp (building a level), mips.cpp,
/// inject.cpp (photons), lookup.cpp, estimate.cpp (memory before building), scene_hash.cpp,
/// field_io.cpp (.vdb).

#include "field_impl.h"

#include "voxcone/core/error.h"
#include "voxcone/core/timer.h"
#include "voxcone/scene/scene.h"

#include <algorithm>

namespace voxcone {

using namespace voxel;

VoxelField::VoxelField() : m_impl(std::make_unique<Impl>()) {}
VoxelField::~VoxelField() = default;
VoxelField::VoxelField(VoxelField&&) noexcept = default;
VoxelField& VoxelField::operator=(VoxelField&&) noexcept = default;

void voxel::fieldCube(const Scene& scene, double padding, DVec3& origin, double& extent) {
  const Bounds3& sb = scene.bounds();
  const DVec3 diag = DVec3(sb.hi) - DVec3(sb.lo);
  const double side = std::max(diag.x, std::max(diag.y, diag.z));
  const double pad = padding * side;
  origin = DVec3(sb.lo) - DVec3(pad);
  // Pad by a relative 1e-6 so the max corner falls inside the last voxel, not on its far face.
  extent = (side + 2.0 * pad) * (1.0 + 1e-6);
}

void VoxelField::checkScene(const Scene& scene, const std::string& what) const {
  const Impl& f = *m_impl;
  if (f.sceneHash != 0 && f.sceneHash != fieldSceneHash(scene))
    throw SettingsError(what + ": the field was built for another scene (its geometry, materials or lights differ)");
  DVec3 origin;
  double extent;
  fieldCube(scene, f.settings.padding, origin, extent);
  const double tol = 1e-9 * std::max(std::abs(extent), 1e-300);
  if (std::abs(extent - f.extent) > tol || glm::length(origin - f.origin) > tol)
    throw SettingsError(what + ": the field was voxelized for another scene (it covers a cube of side " +
                        std::to_string(f.extent) + " at (" + std::to_string(f.origin.x) + ", " + std::to_string(f.origin.y) +
                        ", " + std::to_string(f.origin.z) + "), this scene needs side " + std::to_string(extent) + ")");
}

VoxelField VoxelField::voxelize(const Scene& scene, const VoxelSettings& settings, Progress* progress,
                                const std::vector<Photon>* causticPhotons) {
  if (settings.level < 1 || settings.level > 13)
    throw SettingsError("voxel level must be in [1, 13], got " + std::to_string(settings.level));
  if (settings.coarsestLevel < 0 || settings.coarsestLevel > settings.level)
    throw SettingsError("coarsest voxel level must be in [0, level], got " + std::to_string(settings.coarsestLevel));
  if (!(settings.kernelSigmaVoxels > 0.0f) || settings.kernelSigmaVoxels > 16.0f)
    throw SettingsError("kernel sigma must be in (0, 16] voxels, got " + std::to_string(settings.kernelSigmaVoxels));
  if (settings.causticLevel != 0 && (settings.causticLevel < settings.coarsestLevel || settings.causticLevel > 13))
    throw SettingsError("caustic level must be 0 or in [coarsest level, 13], got " +
                        std::to_string(settings.causticLevel));
  if (scene.triangleCount() == 0 || scene.bounds().empty()) throw SettingsError("cannot voxelize a scene without triangles");
  if (std::all_of(scene.triMaterial.begin(), scene.triMaterial.end(),
                  [&](uint32_t m) { return scene.materials[m].isClearGlass(); }))
    throw SettingsError("cannot voxelize a scene of smooth glass alone: the field holds no glass (nothing to gather)");
  if (!(settings.padding >= 0.0 && settings.padding <= 1.0))
    throw SettingsError("field padding must be in [0, 1] (a fraction of the scene's side), got " +
                        std::to_string(settings.padding));

  // The memory budget, before anything is allocated.
  const uint64_t budget = settings.memoryBudgetBytes == VoxelSettings::kAvailableMemory ? availableMemoryBytes()
                                                                                        : settings.memoryBudgetBytes;
  if (budget > 0 && budget != VoxelSettings::kNoBudget) {
    const std::vector<FieldEstimate> rows = estimate(scene, settings, true, budget);
    if (rows.back().peakBytes > budget) {
      std::string fits = "no level from " + std::to_string(settings.coarsestLevel) + " fits";
      for (auto it = rows.rbegin(); it != rows.rend(); ++it)
        if (it->peakBytes <= budget) {
          fits = "level " + std::to_string(it->level) + " would fit (about " + megabytes(it->peakBytes) + ")";
          break;
        }
      throw SettingsError("voxel level " + std::to_string(settings.level) + " needs about " +
                          megabytes(rows.back().peakBytes) + " (the field " + megabytes(rows.back().fieldBytes) +
                          "), more than the memory budget of " + megabytes(budget) +
                          (settings.memoryBudgetBytes == VoxelSettings::kAvailableMemory ? " (the available memory)" : "") +
                          "; " + fits);
    }
  }

  VoxelField field;
  Impl& f = *field.m_impl;
  f.settings = settings;
  fieldCube(scene, settings.padding, f.origin, f.extent);
  f.originF = Vec3(f.origin);
  f.sceneHash = fieldSceneHash(scene);
  if (!(f.extent > 0.0)) throw SettingsError("cannot voxelize a scene of zero extent");
  f.bounds = Bounds3(Vec3(f.origin), Vec3(f.origin + DVec3(f.extent)));

  auto build = [&](LevelStack& grid, int level, bool countArea, const std::vector<uint64_t>* onlyBricks) {
    Timer timer;
    const double vs = f.voxelSize(level);
    LevelBuilder builder(level, vs, countArea ? f.quantPtr() : nullptr);
    double area = 0.0;
    voxel::voxelizeTriangles(
        scene, f.origin, vs, uint32_t(1) << level, progress,
        [&](voxel::VoxelArrays& run) {
          if (countArea)
            for (float c : run.coverage) area += double(c);
          builder.append(run);
        },
        onlyBricks);
    if (countArea) f.surfaceArea = area * vs * vs;
    grid.levels.push_back(builder.finish());
    grid.levels.back().buildSeconds = timer.seconds();
  };
  build(f.main, settings.level, true, nullptr);
  if (settings.causticLevel > 0) {
    if (!causticPhotons) {
      build(f.caustic, settings.causticLevel, false, nullptr);
      return field;
    }
    // The bricks the photons' footprints reach (splatPhotons' voxel box around each, which
    // holds the nearest-voxel fallback too): the caustic grid keeps only voxels a caustic
    // photon lit, so voxelizing the rest of the scene at the caustic level (0.2 s on the
    // dragon at level 7, for 600 stored photons) changes nothing.
    const double vs = f.voxelSize(settings.causticLevel);
    const double radius = 3.0 * double(settings.kernelSigmaVoxels);
    const int64_t maxIndex = (int64_t(1) << settings.causticLevel) - 1;
    std::vector<uint64_t> bricks;
    for (const Photon& ph : *causticPhotons) {
      const DVec3 q = (DVec3(ph.position) - f.origin) / vs;
      int64_t lo[3], hi[3];
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::clamp(int64_t(std::floor(q[a] - 0.5 - radius)), int64_t(0), maxIndex) >> voxel::kBrickLog2;
        hi[a] = std::clamp(int64_t(std::floor(q[a] + 0.5 + radius)), int64_t(0), maxIndex) >> voxel::kBrickLog2;
      }
      for (int64_t bi = lo[0]; bi <= hi[0]; ++bi)
        for (int64_t bj = lo[1]; bj <= hi[1]; ++bj)
          for (int64_t bk = lo[2]; bk <= hi[2]; ++bk) bricks.push_back(voxel::packBrick(uint32_t(bi), uint32_t(bj), uint32_t(bk)));
    }
    std::sort(bricks.begin(), bricks.end());
    bricks.erase(std::unique(bricks.begin(), bricks.end()), bricks.end());
    build(f.caustic, settings.causticLevel, false, &bricks);
  }
  return field;
}

void VoxelField::inject(const PhotonMaps& photons, Progress* progress) {
  Impl& f = *m_impl;
  if (progress) progress->start("inject", photons.global.size() + photons.caustic.size());
  f.dropped = DVec3(0.0);
  f.globalPhotons = photons.global.size();
  f.causticPhotons = f.caustic.empty() ? 0 : photons.caustic.size();
  // The main grid holds all diffuse radiance: global photons (every path but L S+ D) plus
  // caustic photons (L S+ D): each pass carries the lights' full flux for its own paths.
  f.inject(f.main, PhotonList{{&photons.global, &photons.caustic}}, progress, f.injected);
  DVec3 causticInjected(0.0);
  if (!f.caustic.empty()) {
    // The caustic grid is voxelized fully so that any caustic photon finds its surface; after
    // injection only the voxels a caustic photon reached are kept (model no more than the
    // scene needs), and it gets no mips: caustics are gathered at the shading point.
    f.caustic.levels.resize(1);
    f.inject(f.caustic, PhotonList{{&photons.caustic}}, progress, causticInjected);
    f.caustic.levels.front() = keepLit(f.caustic.levels.front());
  }
  if (progress) progress->finish();
}

VoxelField VoxelField::build(const Scene& scene, const VoxelSettings& settings, const PhotonMaps& traced,
                             const PhotonMaps& held, Progress* progress, BuildStats* stats) {
  Timer t;
  VoxelField field = voxelize(scene, settings, progress, &traced.caustic);
  if (stats) {
    stats->voxelizeSeconds = t.seconds();
    stats->peakAfterVoxelize = peakRssBytes();
  }
  field.relight(held, progress, stats);
  return field;
}

void VoxelField::relight(const PhotonMaps& held, Progress* progress, BuildStats* stats) {
  Timer t;
  inject(held, progress);
  if (stats) {
    stats->injectSeconds = t.seconds();
    stats->peakAfterInject = peakRssBytes();
  }
  t.reset();
  buildMips(progress);
  if (stats) {
    stats->mipsSeconds = t.seconds();
    stats->peakAfterMips = peakRssBytes();
  }
}

void VoxelField::buildMips(Progress* progress) {
  Impl& f = *m_impl;
  for (LevelStack* grid : {&f.main}) {
    if (grid->empty()) continue;
    grid->levels.resize(1);
    if (progress) progress->start("mips", uint64_t(grid->levels.front().level - f.settings.coarsestLevel));
    while (grid->levels.back().level > f.settings.coarsestLevel) {
      if (progress && progress->cancelled()) throw CancelledError();
      Timer t;
      Level parent = restrictLevel(grid->levels.back(), f.settings.mipFilter, f.quantPtr());
      parent.buildSeconds = t.seconds();
      grid->levels.push_back(std::move(parent));
      if (progress) progress->advance(1);
    }
    if (progress) progress->finish();
  }
  // Radiance is final now: decode what the cone lookups read, at the coarser levels.
  for (LevelStack* grid : {&f.main, &f.caustic})
    for (Level& lv : grid->levels)
      if (lv.level <= kConeTableLevel) lv.buildConeTable();
}

const VoxelSettings& VoxelField::settings() const { return m_impl->settings; }
const Bounds3& VoxelField::bounds() const { return m_impl->bounds; }
double VoxelField::voxelSize(int level) const { return m_impl->voxelSize(level); }

std::vector<int> VoxelField::levels() const {
  std::vector<int> out;
  for (const Level& lv : m_impl->main.levels) out.push_back(lv.level);
  return out;
}

Vec3 VoxelField::injectedPower() const { return Vec3(m_impl->injected); }
Vec3 VoxelField::droppedPower() const { return Vec3(m_impl->dropped); }
double VoxelField::surfaceArea() const { return m_impl->surfaceArea; }

uint64_t VoxelField::activeVoxels(int level) const {
  const Level* lv = m_impl->main.find(level);
  return lv ? lv->size() : 0;
}

std::vector<VoxelGridStats> VoxelField::stats() const {
  std::vector<VoxelGridStats> rows;
  for (const Level& lv : m_impl->main.levels) {
    auto row = [&](const char* name, uint64_t bytes, double seconds) {
      VoxelGridStats s;
      s.grid = name;
      s.level = lv.level;
      s.voxelSize = lv.voxelSize;
      s.activeVoxels = lv.size();
      s.leaves = lv.tree ? lv.tree->leafCount() : 0;
      s.bytes = bytes;
      s.seconds = seconds;
      rows.push_back(s);
    };
    const bool finest = &lv == &m_impl->main.levels.front();
    row("topology", lv.topologyBytes(), lv.buildSeconds);
    row("opacity", lv.coverage.capacity() * sizeof(Half), 0.0);
    row("normal", lv.normal.capacity() * sizeof(uint16_t), 0.0);
    if (!lv.axisFraction.empty()) row("axes", lv.axisFraction.capacity() * sizeof(uint8_t), 0.0);
    if (finest) row("diffuse", lv.diffuse.bytes(), 0.0);
    row("radiance", lv.radiance[0].bytes(), finest ? m_impl->main.injectSeconds : 0.0);
    row("radiance_back", lv.radiance[1].bytes(), 0.0);
    if (!lv.coneTable.empty()) row("cone_table", lv.coneTable.capacity() * sizeof(ConeVoxel), 0.0);
  }
  for (const Level& lv : m_impl->caustic.levels) {
    VoxelGridStats s;
    s.grid = "caustic";
    s.level = lv.level;
    s.voxelSize = lv.voxelSize;
    s.activeVoxels = lv.size();
    s.leaves = lv.tree ? lv.tree->leafCount() : 0;
    s.bytes = lv.topologyBytes() + lv.coverage.capacity() * sizeof(Half) + lv.normal.capacity() * sizeof(uint16_t) +
              lv.diffuse.bytes() + lv.radiance[0].bytes() + lv.radiance[1].bytes() +
              lv.coneTable.capacity() * sizeof(ConeVoxel);
    s.seconds = lv.buildSeconds;
    rows.push_back(s);
  }
  return rows;
}

nlohmann::json VoxelField::quantizationJson() const {
  const FieldQuantization& q = m_impl->quant;
  if (!m_impl->settings.measureQuantization) return nullptr;
  return {{"coverage_relative", q.coverage.json()}, {"normal_degrees", q.normal.json()},
          {"radiance_relative", q.radiance.json()}, {"axes_absolute", q.axes.json()}, {"diffuse_absolute", q.diffuse.json()}};
}

uint64_t VoxelField::memoryBytes() const {
  uint64_t total = 0;
  for (const VoxelGridStats& s : stats()) total += s.bytes;
  return total;
}

}  // namespace voxcone

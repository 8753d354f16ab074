/// \file field_io.cpp
/// A field to and from a .vdb file: per level, standard OpenVDB grids (coverage, normal, each
/// side's radiance, the diffuse fraction, the mips' axes) named NAME_L<level>, and the field's
/// settings as file metadata (VoxelField::write, VoxelField::read).

#include "field_impl.h"

#include "voxcone/core/error.h"
#include "voxcone/core/file_io.h"

#include <openvdb/openvdb.h>
#include <openvdb/io/File.h>
#include <openvdb/io/GridDescriptor.h>
#include <openvdb/io/io.h>

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <cstdio>
#include <fstream>
#include <cstdlib>
#include <functional>
#include <limits>
#include <mutex>
#include <optional>

namespace voxcone {

using namespace voxel;

namespace {

std::once_flag g_openvdbInit;

/// Version of the .vdb layout VoxelField::write produces and VoxelField::read accepts.
constexpr int32_t kFieldFileVersion = 2;

/// OpenVDB puts voxel centres at integer index coordinates: voxel (i, j, k) of ours has its
/// centre at origin + (i + 0.5) * voxelSize.
openvdb::math::Transform::Ptr transformFor(const DVec3& origin, double voxelSize) {
  auto xform = openvdb::math::Transform::createLinearTransform(voxelSize);
  xform->postTranslate(openvdb::Vec3d(origin.x, origin.y, origin.z) + openvdb::Vec3d(0.5 * voxelSize));
  return xform;
}

/// A grid whose leaves hold only their active masks until the file asks for their values: the
/// file writes every grid's topology first and then its leaves' values in the same order
/// (Tree::writeBuffers, depth first), and here each leaf's values are made from the level when
/// its turn comes, in a leaf of its own that is freed at once. A grid then costs its masks, not
/// dense leaves: built whole, the dragon's level-10 grids took 1.5 GB of RSS to write (a Vec3s
/// leaf is 6 KB for a surface through a few of its 512 voxels).
template <typename GridT>
class StreamedGrid final : public GridT {
public:
  using ValueT = typename GridT::ValueType;
  using LeafT = typename GridT::TreeType::LeafNodeType;
  using ValueFn = std::function<ValueT(const VoxelRef&)>;

  /// The voxels of `lv` for which `all` or value(voxel) != background.
  StreamedGrid(const Level& lv, ValueT background, bool all, ValueFn value)
      : GridT(background), m_level(lv), m_value(std::move(value)) {
    // The tree itself, not a ValueAccessor: an accessor caches a leaf's value buffer, and asking
    // a partial leaf for it allocates it. Voxels come brick by brick, so the last leaf mostly
    // holds the next voxel.
    auto& tree = this->tree();
    LeafT* leaf = nullptr;
    constexpr int32_t kOrigin = ~int32_t(LeafT::DIM - 1);
    lv.forEachVoxel([&](const VoxelRef& r, uint32_t i, uint32_t j, uint32_t k) {
      if (!all && m_value(r) == background) return;
      const openvdb::Coord c{int32_t(i), int32_t(j), int32_t(k)};
      const openvdb::Coord origin{c.x() & kOrigin, c.y() & kOrigin, c.z() & kOrigin};
      if (!leaf || leaf->origin() != origin) leaf = tree.probeLeaf(origin);
      if (!leaf) {
        // No values yet (PartialCreate): writeBuffers makes them.
        leaf = new LeafT(openvdb::PartialCreate(), origin, background, false);
        tree.addLeaf(leaf);
      }
      leaf->setActiveState(LeafT::coordToOffset(c), true);
    });
  }

  void writeBuffers(std::ostream& os) const override {
    IndexAccessor index(*m_level.tree);
    // The voxels of a leaf come z fastest, four to a brick row: the brick is looked up once for
    // them (every active voxel is the level's, so it is inside it).
    int64_t brick = -1;
    openvdb::Coord brickCoord(std::numeric_limits<int32_t>::min());
    for (auto it = this->tree().cbeginLeaf(); it; ++it) {
      LeafT leaf(it->origin(), this->background(), false);
      for (auto on = it->getValueMask().beginOn(); on; ++on) {
        const openvdb::Coord c = it->offsetToGlobalCoord(on.pos());
        const openvdb::Coord b(c.x() >> 2, c.y() >> 2, c.z() >> 2);
        if (b != brickCoord) {
          brickCoord = b;
          brick = m_level.brickAt(b.x(), b.y(), b.z(), index);
        }
        VoxelRef r{};
        // Made again here, as the mask was made from them: the grid keeps no values.
        if (brick >= 0 && m_level.voxelIn(uint32_t(brick), uint32_t(c.x()), uint32_t(c.y()), uint32_t(c.z()), r))
          leaf.setValueOn(on.pos(), m_value(r));
      }
      leaf.writeBuffers(os, this->saveFloatAsHalf());
    }
  }

private:
  const Level& m_level;
  ValueFn m_value;
};

/// Writes a .vdb as io::File::write does (the same header, file metadata, grid descriptors,
/// topology and buffers), less the per-leaf delayed-load metadata that Archive::writeGrid adds
/// (optional: readers without it read every leaf whole): making it reads every leaf's values
/// before the grid is written, which would allocate StreamedGrid's leaves all at once.
class FieldArchive final : public openvdb::io::Archive {
public:
  void write(std::ostream& os, const openvdb::GridCPtrVec& grids, const openvdb::MetaMap& metadata) const {
    openvdb::io::StreamMetadata::Ptr fileMeta = openvdb::io::getStreamMetadataPtr(os);
    if (!fileMeta) {
      fileMeta = std::make_shared<openvdb::io::StreamMetadata>();
      openvdb::io::setStreamMetadataPtr(os, fileMeta, /*transfer=*/false);
    }
    openvdb::io::setDataCompression(os, compression());
    openvdb::io::setWriteGridStatsMetadata(os, false);
    writeHeader(os, /*seekable=*/true);
    metadata.writeMeta(os);
    const int32_t count = int32_t(grids.size());
    os.write(reinterpret_cast<const char*>(&count), sizeof count);
    for (const openvdb::GridBase::ConstPtr& grid : grids) {
      writeOne(os, *grid, fileMeta);
      // Some compression options are set per grid: back to the file's for the next.
      openvdb::io::setDataCompression(os, compression());
    }
  }

private:
  /// One grid (its name unique in the file), seekable: the descriptor, then the positions
  /// written again once known.
  void writeOne(std::ostream& os, const openvdb::GridBase& grid, const openvdb::io::StreamMetadata::Ptr& fileMeta) const {
    auto gridMeta = std::make_shared<openvdb::io::StreamMetadata>(*fileMeta);
    gridMeta->setHalfFloat(grid.saveFloatAsHalf());
    gridMeta->gridMetadata() = static_cast<const openvdb::MetaMap&>(grid);
    openvdb::io::StreamMetadata::Ptr current = gridMeta;
    openvdb::io::setStreamMetadataPtr(os, current, /*transfer=*/false);
    openvdb::io::GridDescriptor gd(grid.getName(), grid.type(), grid.saveFloatAsHalf());
    gd.writeHeader(os);
    const int64_t offsetPos = int64_t(os.tellp());
    gd.writeStreamPos(os);  // a placeholder until the positions are known
    gd.setGridPos(os.tellp());
    setGridCompression(os, grid);
    grid.writeMeta(os);
    grid.writeTransform(os);
    grid.writeTopology(os);
    gd.setBlockPos(os.tellp());
    grid.writeBuffers(os);
    gd.setEndPos(os.tellp());
    os.seekp(offsetPos, std::ios_base::beg);
    gd.writeStreamPos(os);
    gd.seekToEnd(os);
    openvdb::io::StreamMetadata::Ptr file = fileMeta;
    openvdb::io::setStreamMetadataPtr(os, file, /*transfer=*/false);
  }
};

/// The grids of one level under `prefix` ("" for the main grid, "caustic_" for the caustic
/// grid): coverage and normal of every voxel; each side's radiance, the diffuse fraction and the
/// mips' axis fractions where they differ from their defaults (0, 1, none). Each is a task that
/// builds its topology (write() runs them in parallel), in file order; the values are made as
/// the file is written (StreamedGrid).
using GridTask = std::function<openvdb::GridBase::Ptr()>;
void addLevelGrids(const Level& lv, const DVec3& origin, bool finest, const std::string& prefix, std::vector<GridTask>& tasks) {
  const std::string l = "_L" + std::to_string(lv.level);
  const openvdb::math::Transform::Ptr xform = transformFor(origin, lv.voxelSize);
  auto floatGrid = [&lv, xform, l, prefix](const std::string& name, float background, bool all,
                                           std::function<float(const VoxelRef&)> value) -> GridTask {
    return [=, &lv]() -> openvdb::GridBase::Ptr {
      auto grid = std::make_shared<StreamedGrid<openvdb::FloatGrid>>(lv, background, all, value);
      grid->setName(prefix + name + l);
      grid->setTransform(xform->copy());
      grid->setGridClass(openvdb::GRID_FOG_VOLUME);
      return grid;
    };
  };
  auto vecGrid = [&lv, xform, l, prefix](const std::string& name, bool all, std::function<Vec3(const VoxelRef&)> value) -> GridTask {
    return [=, &lv]() -> openvdb::GridBase::Ptr {
      auto toVdb = [value](const VoxelRef& r) {
        const Vec3 x = value(r);
        return openvdb::Vec3s(x.x, x.y, x.z);
      };
      auto grid = std::make_shared<StreamedGrid<openvdb::Vec3SGrid>>(lv, openvdb::Vec3s(0.0f), all, toVdb);
      grid->setName(prefix + name + l);
      grid->setTransform(xform->copy());
      return grid;
    };
  };
  const Level* level = &lv;
  // The coverage grid's active voxels are the level's (a sliver's coverage may round to zero
  // in half precision: it stays active).
  tasks.push_back(floatGrid("coverage", 0.0f, true, [level](const VoxelRef& r) { return float(level->coverage[r.index]); }));
  tasks.push_back(vecGrid("normal", true, [level](const VoxelRef& r) { return level->normalAt(r.index); }));
  if (lv.lit) {
    tasks.push_back(vecGrid("radiance", false, [level](const VoxelRef& r) { return level->frontAt(r); }));
    tasks.push_back(vecGrid("radiance_back", false, [level](const VoxelRef& r) { return level->backAt(r); }));
  }
  if (!lv.axisFraction.empty())
    tasks.push_back(vecGrid("axes", true, [level](const VoxelRef& r) { return level->axisFractionAt(r.index); }));
  if (finest) tasks.push_back(floatGrid("diffuse", 1.0f, false, [level](const VoxelRef& r) { return level->diffuseAt(r); }));
}

/// One level back from the grids addLevelGrids wrote (missing grids: their defaults).
Level readLevel(openvdb::io::File& file, const std::string& path, const std::string& prefix, int level, double voxelSize,
                bool mip) {
  const std::string l = "_L" + std::to_string(level);
  auto grid = [&](const std::string& name, bool required) -> openvdb::GridBase::Ptr {
    if (!file.hasGrid(prefix + name + l)) {
      if (required) throw Error(path + ": not a voxcone field: no grid '" + prefix + name + l + "'");
      return nullptr;
    }
    return file.readGrid(prefix + name + l);
  };
  auto typed = [&](auto tag, const openvdb::GridBase::Ptr& g, const std::string& name) {
    using GridT = typename decltype(tag)::type;
    auto t = openvdb::gridPtrCast<GridT>(g);
    if (g && !t) throw Error(path + ": grid '" + prefix + name + l + "' has type " + g->type() + ", not " + GridT::gridType());
    return t;
  };
  struct FloatTag { using type = openvdb::FloatGrid; };
  struct VecTag { using type = openvdb::Vec3SGrid; };
  const auto coverage = typed(FloatTag{}, grid("coverage", true), "coverage");
  const auto normal = typed(VecTag{}, grid("normal", true), "normal");
  const auto front = typed(VecTag{}, grid("radiance", false), "radiance");
  const auto back = typed(VecTag{}, grid("radiance_back", false), "radiance_back");
  const auto axes = typed(VecTag{}, grid("axes", mip), "axes");
  const auto diffuse = typed(FloatTag{}, grid("diffuse", false), "diffuse");
  if (bool(front) != bool(back)) throw Error(path + ": grid '" + prefix + "radiance" + l + "' needs its '_back' grid");

  // The voxels in key order, from the coverage grid's active voxels.
  const int64_t res = int64_t(1) << level;
  std::vector<uint64_t> keys;
  keys.reserve(size_t(coverage->activeVoxelCount()));
  for (auto it = coverage->tree().cbeginValueOn(); it; ++it) {
    const openvdb::Coord c = it.getCoord();
    if (c.x() < 0 || c.y() < 0 || c.z() < 0 || c.x() >= res || c.y() >= res || c.z() >= res || !(*it >= 0.0f && *it <= 65504.0f))
      throw Error(path + ": grid '" + prefix + "coverage" + l + "' has a voxel outside the level or a coverage out of range");
    keys.push_back(voxel::packKey(uint32_t(c.x()), uint32_t(c.y()), uint32_t(c.z())));
  }
  tbb::parallel_sort(keys.begin(), keys.end());

  LevelBuilder builder(level, voxelSize);
  auto covAcc = coverage->getConstAccessor();
  auto nrmAcc = normal->getConstAccessor();
  std::optional<openvdb::Vec3SGrid::ConstAccessor> frontAcc, backAcc, axesAcc;
  std::optional<openvdb::FloatGrid::ConstAccessor> diffAcc;
  if (front) frontAcc.emplace(front->getConstAccessor()), backAcc.emplace(back->getConstAccessor());
  if (axes) axesAcc.emplace(axes->getConstAccessor());
  if (diffuse) diffAcc.emplace(diffuse->getConstAccessor());
  const auto vec = [](const openvdb::Vec3s& v) { return Vec3(v.x(), v.y(), v.z()); };
  constexpr size_t kRun = 1 << 16;
  VoxelArrays run;
  for (size_t first = 0; first < keys.size(); first += kRun) {
    run.clear();
    for (size_t n = first; n < std::min(keys.size(), first + kRun); ++n) {
      uint32_t i, j, k;
      voxel::unpackKey(keys[n], i, j, k);
      const openvdb::Coord c{int32_t(i), int32_t(j), int32_t(k)};
      run.keys.push_back(keys[n]);
      run.coverage.push_back(covAcc.getValue(c));
      run.normal.push_back(vec(nrmAcc.getValue(c)));
      if (!mip) run.diffuse.push_back(diffAcc ? diffAcc->getValue(c) : 1.0f);
      if (front) {
        run.radiance.push_back(vec(frontAcc->getValue(c)));
        run.radianceBack.push_back(vec(backAcc->getValue(c)));
      }
      if (axes) run.axisFraction.push_back(vec(axesAcc->getValue(c)));
    }
    builder.append(run);
  }
  Level out = builder.finish();
  out.lit = bool(front);
  return out;
}

}  // namespace

void VoxelField::write(const std::string& path, const nlohmann::json& metadata) const {
  std::call_once(g_openvdbInit, [] { openvdb::initialize(); });
  const Impl& f = *m_impl;
  std::vector<GridTask> tasks;
  for (const Level& lv : f.main.levels) addLevelGrids(lv, f.origin, &lv == &f.main.levels.front(), "", tasks);
  for (const Level& lv : f.caustic.levels) addLevelGrids(lv, f.origin, true, "caustic_", tasks);
  openvdb::GridPtrVec grids(tasks.size());
  tbb::parallel_for(size_t(0), tasks.size(), [&](size_t t) { grids[t] = tasks[t](); });

  openvdb::MetaMap meta;
  // The caller's keys go under "voxcone:" so they never clash with the typed keys below.
  if (metadata.is_object())
    for (auto it = metadata.begin(); it != metadata.end(); ++it)
      meta.insertMeta("voxcone:" + it.key(),
                      openvdb::StringMetadata(it->is_string() ? it->get<std::string>() : it->dump()));
  meta.insertMeta("field_version", openvdb::Int32Metadata(kFieldFileVersion));
  meta.insertMeta("level", openvdb::Int32Metadata(f.settings.level));
  meta.insertMeta("coarsest_level", openvdb::Int32Metadata(f.settings.coarsestLevel));
  meta.insertMeta("caustic_level", openvdb::Int32Metadata(f.caustic.empty() ? 0 : f.settings.causticLevel));
  meta.insertMeta("kernel_sigma", openvdb::FloatMetadata(f.settings.kernelSigmaVoxels));
  meta.insertMeta("padding", openvdb::DoubleMetadata(f.settings.padding));
  meta.insertMeta("mip_filter", openvdb::StringMetadata(f.settings.mipFilter == MipFilter::Box ? "box" : "gaussian"));
  meta.insertMeta("voxel_size", openvdb::DoubleMetadata(f.voxelSize(f.settings.level)));
  meta.insertMeta("origin", openvdb::Vec3DMetadata(openvdb::Vec3d(f.origin.x, f.origin.y, f.origin.z)));
  meta.insertMeta("extent", openvdb::DoubleMetadata(f.extent));
  meta.insertMeta("surface_area", openvdb::DoubleMetadata(f.surfaceArea));
  meta.insertMeta("injected_power", openvdb::Vec3DMetadata(openvdb::Vec3d(f.injected.x, f.injected.y, f.injected.z)));
  meta.insertMeta("dropped_power", openvdb::Vec3DMetadata(openvdb::Vec3d(f.dropped.x, f.dropped.y, f.dropped.z)));
  meta.insertMeta("global_photons", openvdb::Int64Metadata(int64_t(f.globalPhotons)));
  meta.insertMeta("caustic_photons", openvdb::Int64Metadata(int64_t(f.causticPhotons)));
  char hash[17];
  std::snprintf(hash, sizeof hash, "%016llx", (unsigned long long)f.sceneHash);
  meta.insertMeta("scene_hash", openvdb::StringMetadata(hash));

  writeFileAtomic(path, [&](const std::string& tmpPath) {
    try {
      std::ofstream file(tmpPath, std::ios_base::out | std::ios_base::binary | std::ios_base::trunc);
      if (!file) throw Error(path + ": cannot open for writing");
      FieldArchive().write(file, openvdb::GridCPtrVec(grids.begin(), grids.end()), meta);
      file.close();
      if (!file) throw Error(path + ": cannot write OpenVDB file");
    } catch (const openvdb::Exception& e) {
      throw Error(path + ": cannot write OpenVDB file: " + e.what());
    }
  });
}

VoxelField VoxelField::read(const std::string& path) {
  std::call_once(g_openvdbInit, [] { openvdb::initialize(); });
  VoxelField field;
  Impl& f = *field.m_impl;
  try {
    openvdb::io::File file(path);
    file.open(false);  // read every grid whole: each level is decoded once
    const openvdb::MetaMap::Ptr meta = file.getMetadata();
    auto need = [&](const char* key) {
      if (!(*meta)[key]) throw Error(path + ": not a voxcone field: no metadata '" + std::string(key) + "'");
    };
    need("field_version");
    const int32_t version = meta->metaValue<int32_t>("field_version");
    if (version != kFieldFileVersion)
      throw Error(path + ": voxcone field version " + std::to_string(version) + ", this build reads version " +
                  std::to_string(kFieldFileVersion) + " (voxelize the scene again)");
    for (const char* key : {"level", "coarsest_level", "caustic_level", "kernel_sigma", "padding", "mip_filter", "origin",
                            "extent", "surface_area", "injected_power", "dropped_power", "global_photons", "caustic_photons",
                            "scene_hash"})
      need(key);
    VoxelSettings& s = f.settings;
    s.level = meta->metaValue<int32_t>("level");
    s.coarsestLevel = meta->metaValue<int32_t>("coarsest_level");
    s.causticLevel = meta->metaValue<int32_t>("caustic_level");
    s.kernelSigmaVoxels = meta->metaValue<float>("kernel_sigma");
    s.padding = meta->metaValue<double>("padding");
    s.mipFilter = meta->metaValue<std::string>("mip_filter") == "gaussian" ? MipFilter::Gaussian : MipFilter::Box;
    if (s.level < 1 || s.level > 13 || s.coarsestLevel < 0 || s.coarsestLevel > s.level || s.causticLevel < 0 ||
        s.causticLevel > 13)
      throw Error(path + ": voxcone field with levels out of range (level " + std::to_string(s.level) + ", coarsest " +
                  std::to_string(s.coarsestLevel) + ", caustic " + std::to_string(s.causticLevel) + ")");
    const openvdb::Vec3d o = meta->metaValue<openvdb::Vec3d>("origin");
    f.origin = DVec3(o.x(), o.y(), o.z());
    f.originF = Vec3(f.origin);
    f.extent = meta->metaValue<double>("extent");
    if (!(f.extent > 0.0) || !std::isfinite(f.extent)) throw Error(path + ": voxcone field of extent " + std::to_string(f.extent));
    f.bounds = Bounds3(Vec3(f.origin), Vec3(f.origin + DVec3(f.extent)));
    f.surfaceArea = meta->metaValue<double>("surface_area");
    const openvdb::Vec3d inj = meta->metaValue<openvdb::Vec3d>("injected_power"),
                         drop = meta->metaValue<openvdb::Vec3d>("dropped_power");
    f.injected = DVec3(inj.x(), inj.y(), inj.z());
    f.dropped = DVec3(drop.x(), drop.y(), drop.z());
    f.globalPhotons = uint64_t(meta->metaValue<int64_t>("global_photons"));
    f.causticPhotons = uint64_t(meta->metaValue<int64_t>("caustic_photons"));
    f.sceneHash = std::strtoull(meta->metaValue<std::string>("scene_hash").c_str(), nullptr, 16);
    for (int level = s.level; level >= s.coarsestLevel; --level)
      f.main.levels.push_back(readLevel(file, path, "", level, f.voxelSize(level), level != s.level));
    if (s.causticLevel > 0)
      f.caustic.levels.push_back(readLevel(file, path, "caustic_", s.causticLevel, f.voxelSize(s.causticLevel), false));
    file.close();
  } catch (const openvdb::Exception& e) {
    throw Error(path + ": cannot read OpenVDB file: " + e.what());
  }
  for (LevelStack* grid : {&f.main, &f.caustic})
    for (Level& lv : grid->levels)
      if (lv.level <= kConeTableLevel && lv.lit) lv.buildConeTable();
  return field;
}

}  // namespace voxcone

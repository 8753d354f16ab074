#pragma once
/// \file field_impl.h (private to src/voxel/)
/// VoxelField's state, shared by the files that implement it: voxel_field.cpp (building, mips
/// and stats), inject.cpp (photons), lookup.cpp (the lookups), field_io.cpp (.vdb).

#include "level.h"

#include "voxcone/photon/photon_tracer.h"

#include <vector>

namespace voxcone {
namespace voxel {

/// A read-only concatenation of photon lists (the main grid takes the global and the caustic map).
struct PhotonList {
  std::vector<const std::vector<Photon>*> parts;
  size_t size() const {
    size_t n = 0;
    for (const auto* p : parts) n += p->size();
    return n;
  }
  const Photon& operator[](size_t i) const {
    for (const auto* p : parts) {
      if (i < p->size()) return (*p)[i];
      i -= p->size();
    }
    return parts.back()->back();  // unreachable for i < size()
  }
};

}  // namespace voxel

struct VoxelField::Impl {
  using LevelStack = voxel::LevelStack;
  using FieldQuantization = voxel::FieldQuantization;
  using PhotonList = voxel::PhotonList;

  VoxelSettings settings;
  Bounds3 bounds;
  DVec3 origin{0.0};
  Vec3 originF{0.0f};         ///< origin in float, for the cone lookups
  double extent = 0.0;        ///< side of the cube the grid covers, world units
  LevelStack main, caustic;
  double surfaceArea = 0.0;   ///< world units^2, full precision sum at voxelization
  DVec3 injected{0.0}, dropped{0.0};
  uint64_t globalPhotons = 0, causticPhotons = 0;
  uint64_t sceneHash = 0;     ///< fieldSceneHash of the scene voxelized
  FieldQuantization quant;    ///< the main grid's encoding errors (settings.measureQuantization)

  FieldQuantization* quantPtr() { return settings.measureQuantization ? &quant : nullptr; }

  double voxelSize(int level) const { return extent / double(uint64_t(1) << level); }
  /// Splat `photons` into the grid's finest level and turn their flux into radiance (inject.cpp).
  void inject(LevelStack& grid, const PhotonList& photons, Progress* progress, DVec3& injectedOut);
};

}  // namespace voxcone

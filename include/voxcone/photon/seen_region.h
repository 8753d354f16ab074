#pragma once
/// \file seen_region.h
/// Where the camera's gathers read photons: the cells of a uniform grid that hold a surface the
/// camera sees (through mirrors and glass) or one that a gather from such a surface reaches
/// (visual importance traced from the camera, one diffuse bounce deep: Peter and Pietrek 1998
/// trace it further to guide emission; here it measures how many of the photons traced are of
/// use, so that voxcone can trace as many as the seen part needs).

#include "voxcone/core/bounds.h"
#include "voxcone/core/math.h"
#include "voxcone/photon/photon_tracer.h"

#include <array>
#include <cstdint>
#include <vector>

namespace voxcone {

class Accel;
class Scene;
struct PhotonRadianceSettings;

/// A set of grid cells, immutable after construction.
class SeenRegion {
public:
  SeenRegion() = default;
  /// Cells of size `cellSize` (world units, > 0) holding the first non-delta hit of a
  /// `raysX` x `raysY` grid of camera rays over a `width` x `height` image (delta surfaces
  /// followed along their strongest lobe, up to 8 bounces), and the hits of `gathers`
  /// cosine-distributed rays from each of those points (the side the camera sees; none for 0).
  /// Deterministic (no randomness; any thread count).
  SeenRegion(const Scene& scene, const Accel& accel, int width, int height, float cellSize, int raysX = 64,
             int raysY = 64, int gathers = 16);
  /// Add every cell's 26 neighbours, and every facing but the opposite one: the region then
  /// holds every point within a cell of a seen one that does not face away from it.
  void dilate();
  /// Whether worldPos lies in a seen cell on a surface facing as `normal` (a photon's: turned to
  /// the side it arrived on). Cells are kept per facing (the axis and sign the seen side's normal
  /// leans to), so a roof's top in the cell of the ceiling seen beneath it is not seen.
  bool contains(const Vec3& worldPos, const Vec3& normal) const;
  /// Whether the cell of worldPos is in the region on any side.
  bool holdsCell(const Vec3& worldPos) const;
  /// Photons of `photons` in seen cells that `estimate` keeps (PhotonRadianceSettings::keeps).
  uint64_t count(const std::vector<Photon>& photons, const PhotonRadianceSettings& estimate) const;
  size_t cells() const { return m_entries.size(); }
  /// The mean distance from the surfaces a `raysX` x `raysY` grid of camera rays first meets
  /// (through mirrors and glass) to what `gathers` cosine-distributed rays from each hit (rays
  /// that leave the scene left out): how far a gather's cones reach. 0 where none hits.
  static double meanGatherDistance(const Scene& scene, const Accel& accel, int width, int height, int raysX = 32,
                                   int raysY = 32, int gathers = 16);
  /// A sphere around most of what the camera's gathers read: centred at the per-axis median of
  /// the points a `raysX` x `raysY` grid of camera rays first meets and of what `gathers`
  /// cosine-distributed rays from each hit, with the radius that holds the fraction `quantile`
  /// of them (a gather that leaves through a window to ground far outside does not stretch
  /// it). Radius -1 where none hits.
  static Sphere readSphere(const Scene& scene, const Accel& accel, int width, int height, double quantile,
                           int raysX = 32, int raysY = 32, int gathers = 16);
  float cellSize() const { return m_cellSize; }

private:
  static constexpr int kAxisBits = 20;
  static constexpr uint64_t kAxisMask = (uint64_t(1) << kAxisBits) - 1;
  /// An entry is a cell (3 x kAxisBits) above the mask of its facings (bit 2 axis + (1 where the
  /// side faces down that axis)).
  static constexpr int kFacingBits = 6;
  static constexpr uint64_t kAllFacings = (uint64_t(1) << kFacingBits) - 1;
  /// At most this many cells in the dense grid of index() (16 MB).
  static constexpr uint64_t kMaxDenseCells = uint64_t(1) << 24;
  std::array<uint64_t, 3> cellCoords(const Vec3& worldPos) const;
  uint64_t cellOf(const Vec3& worldPos) const;
  /// The facing of unit normal n: 2 axis + (1 where its component along that axis is negative).
  static int facingOf(const Vec3& n);
  /// The facings held in the cell of worldPos (0: the cell is not in the region).
  uint64_t facingsAt(const Vec3& worldPos) const;
  /// Sort entries by cell and merge each cell's into one (the union of their facings).
  static void mergeCells(std::vector<uint64_t>& entries);
  /// Rebuild m_dense from m_entries (left empty where the cells' box is too large).
  void index();
  float m_cellSize = 1.0f;
  Vec3 m_origin{0.0f};
  std::vector<uint64_t> m_entries;  ///< sorted by cell, one per cell
  std::vector<uint8_t> m_dense;     ///< the facings of each cell of the entries' box (index())
  std::array<uint64_t, 3> m_denseLo{}, m_denseSize{};
};

}  // namespace voxcone

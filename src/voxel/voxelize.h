#pragma once
/// \file voxelize.h (private to src/voxel/)
/// Triangle voxelization into plain sorted arrays, free of OpenVDB types so that it compiles
/// fast; level.cpp (LevelBuilder) turns the arrays into the sparse OpenVDB-indexed levels.

#include "voxcone/core/math.h"
#include "voxcone/core/progress.h"

#include <cstdint>
#include <array>
#include <functional>
#include <vector>

namespace voxcone {

class Scene;

namespace voxel {

/// Voxels are grouped in 4^3 bricks and bricks in 4^3 superbricks (16^3 voxels). Inside either,
/// cell (i, j, k) is bit (i&3)<<4 | (j&3)<<2 | (k&3) of a 64-bit mask.
constexpr int kBrickLog2 = 2;
constexpr int kSuperLog2 = 4;
/// Bits per coordinate in a packed brick or superbrick coordinate: level 13 has 2^11 bricks
/// across, 19 is ample (3 x 19 + 6 < 64).
constexpr int kBrickCoordBits = 19;
constexpr uint64_t kBrickCoordMask = (uint64_t(1) << kBrickCoordBits) - 1;

/// Packed brick coordinate (bi, bj, bk), each in [0, 2^19) (the caustic grid's brick lists).
inline uint64_t packBrick(uint32_t bi, uint32_t bj, uint32_t bk) {
  return (uint64_t(bi) << (2 * kBrickCoordBits)) | (uint64_t(bj) << kBrickCoordBits) | uint64_t(bk);
}
inline void unpackBrick(uint64_t brick, uint32_t& bi, uint32_t& bj, uint32_t& bk) {
  bi = uint32_t(brick >> (2 * kBrickCoordBits));
  bj = uint32_t((brick >> kBrickCoordBits) & kBrickCoordMask);
  bk = uint32_t(brick & kBrickCoordMask);
}
/// Bit of cell (i, j, k) inside a 4^3 mask (of a brick's voxels, or of a superbrick's bricks
/// when given brick coordinates), [0, 64).
inline uint32_t brickBit(uint32_t i, uint32_t j, uint32_t k) { return ((i & 3u) << 4) | ((j & 3u) << 2) | (k & 3u); }
/// Voxel key: packed superbrick coordinate << 12 | the brick's bit in its superbrick << 6 | the
/// voxel's bit in its brick. Sorting by key groups the voxels by superbrick, then by brick in
/// mask-bit order, then in mask-bit order inside a brick (what the rank arithmetic of the
/// field's two-level index needs). key >> 6 names the brick, key >> 12 the superbrick.
inline uint64_t packKey(uint32_t i, uint32_t j, uint32_t k) {
  return (packBrick(i >> kSuperLog2, j >> kSuperLog2, k >> kSuperLog2) << 12) |
         (uint64_t(brickBit(i >> kBrickLog2, j >> kBrickLog2, k >> kBrickLog2)) << 6) | brickBit(i, j, k);
}
inline void unpackKey(uint64_t key, uint32_t& i, uint32_t& j, uint32_t& k) {
  unpackBrick(key >> 12, i, j, k);
  const uint32_t b = uint32_t((key >> 6) & 63u), v = uint32_t(key & 63u);
  i = (i << 4) | ((b >> 4) << 2) | (v >> 4);
  j = (j << 4) | (((b >> 2) & 3u) << 2) | ((v >> 2) & 3u);
  k = (k << 4) | ((b & 3u) << 2) | (v & 3u);
}

/// Per-voxel values of a run of voxels in full precision, sorted by key (transient: the field
/// stores them compactly).
struct VoxelArrays {
  std::vector<uint64_t> keys;
  /// Finest level: surface area inside the voxel / voxelSize^2 (may exceed 1 for folded or
  /// tilted surfaces). Coarser levels: opacity (mean child coverage), in [0, 1].
  std::vector<float> coverage;
  std::vector<Vec3> normal;    ///< unit
  /// Finest level: the fraction of the voxel's surface area that is diffuse (gathers light);
  /// mirrors, metals and glossy surfaces are the rest. Empty at coarser levels.
  std::vector<float> diffuse;
  std::vector<Vec3> radiance;      ///< W/(sr m^2) of the front side; empty until injection
  std::vector<Vec3> radianceBack;  ///< of the back side (see Level::radiance)
  /// Coarser levels only: opacity-weighted mean of |normal| per axis (what a ray along an axis
  /// sees of the surfaces); empty at the finest level, where |normal| stands in.
  std::vector<Vec3> axisFraction;
  size_t size() const { return keys.size(); }
  void clear() { *this = VoxelArrays(); }
};

/// Receives the voxels of a level in runs, each sorted by key and after every earlier run's.
using VoxelSink = std::function<void(VoxelArrays&)>;

/// Voxelize every triangle of `scene` into a grid of `resolution`^3 voxels of `voxelSize`
/// (world units) whose lower corner is `origin`, handing the voxels to `sink` in key order.
/// Streamed: the space is cut into slabs of superbrick columns along x, each holding at most
/// about kRegionContributions (voxel, triangle) overlaps, and one slab is voxelized at a time,
/// so the transient records never hold the whole level. With `onlyBricks` (sorted packBrick
/// keys), only the voxels of those bricks (and only the triangles that reach one).
/// Deterministic at any thread count. Returns the number of slabs.
size_t voxelizeTriangles(const Scene& scene, const DVec3& origin, double voxelSize, uint32_t resolution,
                         Progress* progress, const VoxelSink& sink, const std::vector<uint64_t>* onlyBricks = nullptr);

/// An upper bound on the active voxels of that grid: the sum of the triangles' voxel boxes.
uint64_t voxelBoxBound(const Scene& scene, const DVec3& origin, double voxelSize, uint32_t resolution);

/// The (voxel, triangle) overlaps one slab of voxelizeTriangles holds at most, estimated from
/// the triangles' voxel ranges (an upper bound): 48 bytes each while the slab is sorted.
constexpr size_t kRegionContributions = size_t(1) << 20;

/// Akenine-Möller (2001) triangle/box overlap by the separating axis theorem; the box is
/// centred at `center` with half size `halfSize` on every axis.
bool triangleBoxOverlap(const DVec3& center, double halfSize, const DVec3 tri[3]);

/// Area of the part of triangle `tri` inside the box [lo, lo + 1]^3 (Sutherland-Hodgman
/// clipping against the 6 planes, then the polygon's area), in the triangle's units squared.
double clippedTriangleArea(const DVec3 tri[3], const DVec3& lo);

}  // namespace voxel
}  // namespace voxcone

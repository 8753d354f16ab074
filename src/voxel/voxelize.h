#pragma once
/// \file voxelize.h (private to src/voxel/)
/// Triangle voxelization into plain sorted arrays, free of OpenVDB types so that it compiles
/// fast; voxel_field.cpp turns the arrays into the sparse OpenVDB-indexed levels.

#include "voxcone/core/math.h"
#include "voxcone/core/progress.h"

#include <cstdint>
#include <array>
#include <vector>

namespace voxcone {

class Scene;

namespace voxel {

/// Voxels are grouped in 4^3 bricks: bit ((i&3)<<4 | (j&3)<<2 | (k&3)) of a 64-bit mask.
constexpr int kBrickLog2 = 2;
/// Bits per brick coordinate in a packed key: level 13 has 2^11 bricks across, 19 is ample.
constexpr int kBrickCoordBits = 19;
constexpr uint64_t kBrickCoordMask = (uint64_t(1) << kBrickCoordBits) - 1;

/// Packed brick coordinate (bi, bj, bk), each in [0, 2^19).
inline uint64_t packBrick(uint32_t bi, uint32_t bj, uint32_t bk) {
  return (uint64_t(bi) << (2 * kBrickCoordBits)) | (uint64_t(bj) << kBrickCoordBits) | uint64_t(bk);
}
inline void unpackBrick(uint64_t brick, uint32_t& bi, uint32_t& bj, uint32_t& bk) {
  bi = uint32_t(brick >> (2 * kBrickCoordBits));
  bj = uint32_t((brick >> kBrickCoordBits) & kBrickCoordMask);
  bk = uint32_t(brick & kBrickCoordMask);
}
/// Bit of voxel (i, j, k) inside its brick's 64-bit mask, [0, 64).
inline uint32_t brickBit(uint32_t i, uint32_t j, uint32_t k) { return ((i & 3u) << 4) | ((j & 3u) << 2) | (k & 3u); }
/// Voxel key: packed brick coordinate << 6 | bit in the brick. Sorting by key groups the
/// voxels by brick, in mask-bit order inside a brick (what the index arithmetic needs).
inline uint64_t packKey(uint32_t i, uint32_t j, uint32_t k) {
  return (packBrick(i >> kBrickLog2, j >> kBrickLog2, k >> kBrickLog2) << 6) | brickBit(i, j, k);
}
inline void unpackKey(uint64_t key, uint32_t& i, uint32_t& j, uint32_t& k) {
  unpackBrick(key >> 6, i, j, k);
  const uint32_t bit = uint32_t(key & 63u);
  i = (i << 2) | (bit >> 4);
  j = (j << 2) | ((bit >> 2) & 3u);
  k = (k << 2) | (bit & 3u);
}

/// Per-voxel values of one level in full precision, voxels sorted by key (transient: the
/// field stores them compactly).
struct VoxelArrays {
  std::vector<uint64_t> keys;
  /// Finest level: surface area inside the voxel / voxelSize^2 (may exceed 1 for folded or
  /// tilted surfaces). Coarser levels: opacity (mean child coverage), in [0, 1].
  std::vector<float> coverage;
  std::vector<Vec3> normal;    ///< unit
  std::vector<Vec3> albedo;    ///< diffuse albedo, area-weighted over all the voxel's surface
  std::vector<Vec3> radiance;      ///< W/(sr m^2) of the front side; empty until injection
  std::vector<Vec3> radianceBack;  ///< of the back side (see Level::radiance)
  /// Coarser levels only: opacity-weighted mean of |normal| per axis (what a ray along an axis
  /// sees of the surfaces); empty at the finest level, where |normal| stands in.
  std::vector<Vec3> axisFraction;
  size_t size() const { return keys.size(); }
};

/// Voxelize every triangle of `scene` into a grid of `resolution`^3 voxels of `voxelSize`
/// (world units) whose lower corner is `origin`. With `onlyBricks` (sorted packBrick keys),
/// only the voxels of those bricks (and only the triangles that reach one). Deterministic at
/// any thread count.
VoxelArrays voxelizeTriangles(const Scene& scene, const DVec3& origin, double voxelSize, uint32_t resolution,
                              Progress* progress, const std::vector<uint64_t>* onlyBricks = nullptr);

/// Akenine-Möller (2001) triangle/box overlap by the separating axis theorem; the box is
/// centred at `center` with half size `halfSize` on every axis.
bool triangleBoxOverlap(const DVec3& center, double halfSize, const DVec3 tri[3]);

/// Area of the part of triangle `tri` inside the box [lo, lo + 1]^3 (Sutherland-Hodgman
/// clipping against the 6 planes, then the polygon's area), in the triangle's units squared.
double clippedTriangleArea(const DVec3 tri[3], const DVec3& lo);

}  // namespace voxel
}  // namespace voxcone

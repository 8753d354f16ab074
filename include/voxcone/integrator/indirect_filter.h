#pragma once
/// \file indirect_filter.h
/// The screen-space filter of indirect light that renderImage applies for integrators with an
/// indirect filter radius (voxcone's `filter`): a cross-bilateral filter (Eisemann & Durand
/// 2004; the geometry-aware weights of edge-avoiding filters, Dammertz et al. 2010, "Edge-
/// Avoiding A-Trous Wavelet Transform for fast Global Illumination Filtering") over each
/// pixel's indirect light at camera-visible diffuse surfaces. Indirect light there is smooth
/// along a surface while the cones' estimate of it is noisy, so averaging neighbours that see
/// the same surface trades noise for a little blur, and never mixes surfaces: a neighbour
/// counts only on the same material, with a normal within 25 degrees, within two of the
/// pixel's footprints of its tangent plane, and reachable from the pixel through a chain of
/// linked neighbours (`link`: the integrator's exact rays between adjacent pixels' points), so
/// light never crosses an occluder thinner than a pixel, such as a wall seen edge-on between two
/// rooms that share one floor.

#include "voxcone/core/math.h"

#include <vector>

namespace voxcone {

/// Per-pixel inputs of filterIndirect, row-major, width x height.
struct IndirectBuffer {
  int width = 0, height = 0;
  std::vector<Vec3> indirect;      ///< the pixel's indirect light (mean over its samples)
  std::vector<Vec3> position;      ///< mean first-hit position of its samples, world space
  std::vector<Vec3> normal;        ///< unit geometric normal of that surface, viewer side
  std::vector<uint32_t> material;
  std::vector<float> footprint;    ///< world-space width of the pixel at its hit (> 0)
  std::vector<uint8_t> filterable; ///< every sample saw this one surface (else kept as is)
  /// Whether the pixel holds an estimate of its own (1) or only takes its neighbours' (0: its
  /// `indirect` is not read). Empty: every pixel has one.
  std::vector<uint8_t> estimated;
  /// Bit 0: the pixel and its right neighbour see each other's points; bit 1: the same for the
  /// one below. Empty: every pair of adjacent pixels is linked.
  std::vector<uint8_t> link;
  /// How far (world units) the pixel's light may be carried, and taken from: a neighbour counts
  /// only within the smaller of the two pixels' reaches (surfaceReach). Empty: no limit.
  std::vector<float> reach;
};

/// Each filterable pixel's reach: `scale` times the world distance from its point to the nearest
/// point of another surface within `radius` pixels in the image (looking along its row, its
/// column and both diagonals, past up to two pixels that see both surfaces, to the first pixel of
/// another; a surface far behind an outline is far in the world too); infinite where there is
/// none. Near a concave edge (a wall under a ceiling) the indirect light falls within about that
/// distance of the edge (the other surface hides part of the room), so a filter that averages
/// over more carries the brighter light from farther away into the edge: 3-5% brighter 32x32
/// blocks along a room's wall-ceiling edges.
std::vector<float> surfaceReach(const IndirectBuffer& in, int radius, float scale);

/// Whether adjacent pixels p and q (filterable) see one surface by the filter's tests: the same
/// material, normals within 25 degrees, q within two of p's footprints of p's tangent plane.
bool sameFilterSurface(const IndirectBuffer& in, size_t p, size_t q);
/// Whether a point (position, unit normal, material) lies on filterable pixel p's surface by
/// the same tests.
bool onFilterSurface(const IndirectBuffer& in, size_t p, const Vec3& position, const Vec3& normal, uint32_t material);

/// The filtered indirect light of every pixel: filterable pixels take the weighted mean of the
/// estimated filterable pixels within `radius` (pixels) that pass the surface tests and are
/// reachable along the pixel's row and then a column, through links (separable: a row pass,
/// then a column pass over its sums), with Gaussian weights of standard deviation radius / 2 in
/// the image times the cosine of the normals to the eighth power; the others, and any that
/// reach no estimated pixel, keep their own value. Deterministic (no order dependence).
std::vector<Vec3> filterIndirect(const IndirectBuffer& in, int radius);

/// The filterable pixels that filterIndirect cannot fill: no estimated pixel (themselves
/// included) is among their reachable neighbours within `radius`. 1 marks one.
std::vector<uint8_t> unfilledPixels(const IndirectBuffer& in, int radius);

}  // namespace voxcone

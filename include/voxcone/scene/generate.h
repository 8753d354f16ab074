#pragma once
/// \file generate.h
/// Meshes of any size for the structures and scaling studies, and a binary PLY writer.

#include "voxcone/scene/mesh.h"

#include <cstdint>
#include <string>

namespace voxcone {

/// A closed tube along a (2,3) torus knot with a rippled surface: a grid of `segments` rings of
/// `sides` vertices, 2 * segments * sides triangles, chosen (segments = 8 sides) as close to
/// `targetTriangles` as the grid allows. The knot is about 6.1 x 6.3 x 2.7 around the origin;
/// its strands pass in front of each other, so rays see depth complexity, and it has no
/// degenerate triangles. Throws SettingsError below 48 or above 2^30 triangles.
TriangleMesh makeKnotMesh(uint64_t targetTriangles);

/// Write positions and triangles as binary little-endian PLY, atomically (a temporary file
/// renamed into place). Throws Error when the file cannot be written.
void writePly(const std::string& path, const TriangleMesh& mesh);

}  // namespace voxcone

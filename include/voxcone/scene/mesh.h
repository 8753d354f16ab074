#pragma once
/// \file mesh.h
/// Triangle meshes as loaded from files (OBJ, PLY), before they are placed in a scene.

#include "voxcone/core/bounds.h"
#include "voxcone/core/math.h"

#include <cstdint>
#include <string>
#include <vector>

namespace voxcone {

/// A material defined by a mesh file (OBJ's MTL). Converted to a Material by the scene loader.
struct MeshMaterial {
  std::string name;
  Vec3 kd{0.0f};   ///< diffuse reflectance
  Vec3 ks{0.0f};   ///< specular reflectance
  Vec3 ke{0.0f};   ///< emitted radiance (`Ke`): makes the surface emissive
  float ns = 0.0f; ///< Phong exponent
  float ni = 1.0f; ///< index of refraction
  int illum = 2;   ///< MTL illumination model
  std::string mapKd; ///< `map_Kd`: the diffuse texture's file as the MTL names it (relative to the OBJ's folder)
};

/// Indexed triangle mesh in its file's coordinates.
struct TriangleMesh {
  std::vector<Vec3> positions;
  std::vector<Vec3> normals;           ///< per vertex; empty when the file has none
  std::vector<Vec2> uvs;               ///< per vertex texture coordinates; empty when the file has none
  std::vector<UVec3> triangles;        ///< vertex indices into positions (and normals)
  std::vector<int32_t> faceMaterial;   ///< per triangle index into `materials`; empty or -1 = none
  std::vector<MeshMaterial> materials; ///< materials the file defines (OBJ+MTL)

  size_t triangleCount() const { return triangles.size(); }
  Bounds3 bounds() const {
    Bounds3 b;
    for (const Vec3& p : positions) b.extend(p);
    return b;
  }
};

/// Load a PLY file (ascii, binary_little_endian, binary_big_endian). Reads x,y,z (float or
/// double), optional nx,ny,nz, and faces from `vertex_indices` or `vertex_index` lists with
/// count type uchar/ushort/int (and their aliases); other properties and elements are skipped;
/// polygons are fan-triangulated. Throws MeshError naming the file and what is wrong.
TriangleMesh loadPly(const std::string& path);
/// loadPly on the bytes of a file named `name` (fuzzing, tests).
TriangleMesh parsePly(std::string bytes, const std::string& name);

/// Load an OBJ file with tinyobjloader; its MTL library must exist (a missing .mtl is an error).
/// Polygons are triangulated; per-face materials are kept. Throws MeshError.
TriangleMesh loadObj(const std::string& path);
/// loadObj on the text of a file named `name` and of the one material library it may use.
TriangleMesh parseObj(const std::string& objText, const std::string& mtlText, const std::string& name);

/// Load by extension (.ply or .obj, case-insensitive). Throws MeshError for anything else.
TriangleMesh loadMesh(const std::string& path);

}  // namespace voxcone

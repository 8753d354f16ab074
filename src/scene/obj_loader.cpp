/// \file obj_loader.cpp
/// Wavefront OBJ loading through tinyobjloader, and loadMesh (dispatch by file extension).

#include "voxcone/core/error.h"
#include "voxcone/scene/mesh.h"

#include <tiny_obj_loader.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <filesystem>
#include <string>
#include <system_error>
#include <unordered_map>
#include <vector>

namespace voxcone {
namespace {

/// First line of a tinyobjloader message, without its "WARN: "/"ERROR: " style noise.
std::string firstLine(const std::string& s) {
  std::string line = s.substr(0, s.find('\n'));
  while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
  return line;
}

/// The warning line containing `needle`, or an empty string.
std::string lineWith(const std::string& text, const std::string& needle) {
  const size_t at = text.find(needle);
  if (at == std::string::npos) return {};
  const size_t begin = text.rfind('\n', at);
  return firstLine(text.substr(begin == std::string::npos ? 0 : begin + 1));
}

Vec3 toVec3(const tinyobj::real_t* v) { return Vec3(float(v[0]), float(v[1]), float(v[2])); }

}  // namespace

namespace {
TriangleMesh meshFromReader(const tinyobj::ObjReader& reader, bool ok, const std::string& path);
/// Polygons triangulated, no vertex colours.
tinyobj::ObjReaderConfig objConfig() {
  tinyobj::ObjReaderConfig config;
  config.triangulate = true;
  config.vertex_color = false;
  return config;
}
}  // namespace

TriangleMesh loadObj(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw MeshError(path, "cannot open file: no such file");
  if (std::filesystem::is_directory(path, ec)) throw MeshError(path, "cannot open file: is a directory");

  tinyobj::ObjReader reader;
  const bool ok = reader.ParseFromFile(path, objConfig());
  return meshFromReader(reader, ok, path);
}

TriangleMesh parseObj(const std::string& objText, const std::string& mtlText, const std::string& name) {
  tinyobj::ObjReader reader;
  const bool ok = reader.ParseFromString(objText, mtlText, objConfig());
  return meshFromReader(reader, ok, name);
}

namespace {
/// The mesh of a parsed OBJ, every corner validated; errors name `path`.
TriangleMesh meshFromReader(const tinyobj::ObjReader& reader, bool ok, const std::string& path) {
  if (!ok || !reader.Error().empty()) {
    const std::string msg = firstLine(reader.Error());
    throw MeshError(path, msg.empty() ? "cannot parse OBJ" : msg);
  }

  // tinyobjloader only warns about these; for a renderer they are errors. A missing MTL library
  // would silently drop every material (and emitter).
  const std::string& warn = reader.Warning();
  for (const char* needle : {"Material file [", "Failed to load material file"}) {
    const std::string line = lineWith(warn, needle);
    if (!line.empty()) throw MeshError(path, "material library not found (" + line + ")");
  }
  for (const char* needle : {"indices out of bounds", "invalid vertex index"}) {
    const std::string line = lineWith(warn, needle);
    if (!line.empty()) throw MeshError(path, line);
  }

  const tinyobj::attrib_t& attrib = reader.GetAttrib();
  const std::vector<tinyobj::shape_t>& shapes = reader.GetShapes();
  const size_t numPositions = attrib.vertices.size() / 3;
  const size_t numNormals = attrib.normals.size() / 3;
  const size_t numTexcoords = attrib.texcoords.size() / 2;

  TriangleMesh mesh;
  for (const tinyobj::material_t& m : reader.GetMaterials()) {
    MeshMaterial mm;
    mm.name = m.name;
    mm.kd = toVec3(m.diffuse);
    mm.ks = toVec3(m.specular);
    mm.ke = toVec3(m.emission);
    mm.ns = float(m.shininess);
    mm.ni = float(m.ior);
    mm.illum = m.illum;
    mm.mapKd = m.diffuse_texname;
    mesh.materials.push_back(std::move(mm));
  }

  // Validate every corner, and find out whether all corners carry a normal (a texture
  // coordinate).
  bool allNormals = true, allTexcoords = true;
  size_t corners = 0;
  for (size_t s = 0; s < shapes.size(); ++s) {
    const tinyobj::mesh_t& m = shapes[s].mesh;
    size_t offset = 0;
    for (size_t f = 0; f < m.num_face_vertices.size(); ++f) {
      const size_t n = m.num_face_vertices[f];
      if (offset + n > m.indices.size())
        throw MeshError(path, "shape '" + shapes[s].name + "': inconsistent face data");
      for (size_t k = 0; k < n; ++k) {
        const tinyobj::index_t& idx = m.indices[offset + k];
        if (idx.vertex_index < 0 || size_t(idx.vertex_index) >= numPositions)
          throw MeshError(path, "shape '" + shapes[s].name + "', face " + std::to_string(f) +
                                    ": vertex index out of range");
        if (idx.normal_index >= 0 && size_t(idx.normal_index) >= numNormals)
          throw MeshError(path, "shape '" + shapes[s].name + "', face " + std::to_string(f) +
                                    ": normal index out of range");
        if (idx.texcoord_index >= 0 && size_t(idx.texcoord_index) >= numTexcoords)
          throw MeshError(path, "shape '" + shapes[s].name + "', face " + std::to_string(f) +
                                    ": texture coordinate index out of range");
        if (idx.normal_index < 0) allNormals = false;
        if (idx.texcoord_index < 0) allTexcoords = false;
      }
      offset += n;
      corners += n;
    }
  }
  allNormals = allNormals && corners > 0;
  allTexcoords = allTexcoords && corners > 0;

  // Corner -> mesh vertex. Without normals and texture coordinates the file's positions are
  // used as they are; with them each distinct (position, normal, texture coordinate) triple
  // becomes one vertex, since TriangleMesh shares one index between them.
  struct CornerHash {
    size_t operator()(const std::array<int, 3>& k) const {
      uint64_t h = uint64_t(uint32_t(k[0])) * 0x9E3779B97F4A7C15ull;
      h ^= (uint64_t(uint32_t(k[1])) + 0x632BE59BD9B4E019ull) * 0xC2B2AE3D27D4EB4Full;
      h ^= (uint64_t(uint32_t(k[2])) + 0x85EBCA77C2B2AE63ull) * 0x165667B19E3779F9ull;
      return size_t(h ^ (h >> 29));
    }
  };
  std::unordered_map<std::array<int, 3>, uint32_t, CornerHash> cornerToVertex;
  const bool split = allNormals || allTexcoords;
  if (split) {
    cornerToVertex.reserve(corners);
  } else {
    mesh.positions.reserve(numPositions);
    for (size_t i = 0; i < numPositions; ++i) mesh.positions.push_back(toVec3(&attrib.vertices[3 * i]));
  }
  auto vertexOf = [&](const tinyobj::index_t& idx) -> uint32_t {
    if (!split) return uint32_t(idx.vertex_index);
    const std::array<int, 3> key{idx.vertex_index, allNormals ? idx.normal_index : -1,
                                 allTexcoords ? idx.texcoord_index : -1};
    const auto [it, inserted] = cornerToVertex.try_emplace(key, uint32_t(mesh.positions.size()));
    if (inserted) {
      mesh.positions.push_back(toVec3(&attrib.vertices[3 * size_t(idx.vertex_index)]));
      if (allNormals) mesh.normals.push_back(toVec3(&attrib.normals[3 * size_t(idx.normal_index)]));
      if (allTexcoords) {
        const size_t t = 2 * size_t(idx.texcoord_index);
        mesh.uvs.emplace_back(float(attrib.texcoords[t]), float(attrib.texcoords[t + 1]));
      }
    }
    return it->second;
  };

  // Triangles (tinyobjloader has triangulated already; fan-triangulate anything left over).
  bool anyMaterial = false;
  std::vector<int32_t> faceMaterial;
  for (const tinyobj::shape_t& shape : shapes) {
    const tinyobj::mesh_t& m = shape.mesh;
    size_t offset = 0;
    for (size_t f = 0; f < m.num_face_vertices.size(); ++f) {
      const size_t n = m.num_face_vertices[f];
      int32_t mat = f < m.material_ids.size() ? m.material_ids[f] : -1;
      if (mat < 0 || size_t(mat) >= mesh.materials.size()) mat = -1;
      if (n >= 3) {
        const uint32_t v0 = vertexOf(m.indices[offset]);
        uint32_t prev = vertexOf(m.indices[offset + 1]);
        for (size_t k = 2; k < n; ++k) {
          const uint32_t v = vertexOf(m.indices[offset + k]);
          mesh.triangles.emplace_back(v0, prev, v);
          faceMaterial.push_back(mat);
          anyMaterial = anyMaterial || mat >= 0;
          prev = v;
        }
      }
      offset += n;
    }
  }
  if (anyMaterial) mesh.faceMaterial = std::move(faceMaterial);
  return mesh;
}
}  // namespace

TriangleMesh loadMesh(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  if (ext == ".ply") return loadPly(path);
  if (ext == ".obj") return loadObj(path);
  throw MeshError(path, "unknown mesh format '" + ext + "' (expected .ply or .obj)");
}

}  // namespace voxcone

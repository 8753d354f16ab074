// Generated meshes (generate.h).

#include "voxcone/scene/generate.h"

#include "voxcone/core/error.h"
#include "voxcone/core/file_io.h"

#include <cmath>
#include <cstring>
#include <fstream>

namespace voxcone {

namespace {

/// The knot's centre line at parameter s in [0, 1).
DVec3 knotPoint(double s) {
  const double phi = 2.0 * M_PI * s;
  const double r = 2.0 + std::cos(3.0 * phi);
  return {r * std::cos(2.0 * phi), r * std::sin(2.0 * phi), -std::sin(3.0 * phi)};
}

}  // namespace

TriangleMesh makeKnotMesh(uint64_t targetTriangles) {
  if (targetTriangles < 48 || targetTriangles > (uint64_t(1) << 30))
    throw SettingsError("generated mesh: triangles must be in [48, 2^30], got " + std::to_string(targetTriangles));
  // 2 * segments * sides = target with segments = 8 sides.
  const uint32_t sides = std::max<uint32_t>(3, static_cast<uint32_t>(std::lround(std::sqrt(double(targetTriangles) / 16.0))));
  const uint32_t segments =
      std::max<uint32_t>(8, static_cast<uint32_t>(std::llround(double(targetTriangles) / (2.0 * sides))));
  TriangleMesh mesh;
  mesh.positions.reserve(size_t(segments) * sides);
  mesh.triangles.reserve(size_t(segments) * sides * 2);
  for (uint32_t i = 0; i < segments; ++i) {
    const double s = double(i) / segments;
    const DVec3 c = knotPoint(s);
    const DVec3 tangent = glm::normalize(knotPoint(s + 1e-6) - knotPoint(s - 1e-6));
    // The frame's first axis: the direction away from the torus' axis, made normal to the
    // tangent (never parallel to it: the knot always winds around that axis).
    const DVec3 radial = glm::normalize(DVec3(c.x, c.y, 0.0));
    const DVec3 n = glm::normalize(radial - glm::dot(radial, tangent) * tangent);
    const DVec3 b = glm::cross(tangent, n);
    for (uint32_t j = 0; j < sides; ++j) {
      const double theta = 2.0 * M_PI * j / sides;
      // Ripples along and around the tube (integer frequencies keep the surface closed).
      const double radius = 0.32 * (1.0 + 0.12 * std::sin(60.0 * M_PI * s) * std::cos(3.0 * theta) +
                                    0.05 * std::sin(2.0 * M_PI * 173.0 * s + 5.0 * theta));
      mesh.positions.push_back(Vec3(c + radius * (std::cos(theta) * n + std::sin(theta) * b)));
    }
  }
  for (uint32_t i = 0; i < segments; ++i) {
    const uint32_t i1 = (i + 1) % segments;
    for (uint32_t j = 0; j < sides; ++j) {
      const uint32_t j1 = (j + 1) % sides;
      const uint32_t a = i * sides + j, bb = i * sides + j1, c = i1 * sides + j, d = i1 * sides + j1;
      mesh.triangles.push_back({a, c, d});
      mesh.triangles.push_back({a, d, bb});
    }
  }
  return mesh;
}

void writePly(const std::string& path, const TriangleMesh& mesh) {
  writeFileAtomic(path, [&](const std::string& tmp) {
    std::ofstream f(tmp, std::ios::binary);
    f << "ply\nformat binary_little_endian 1.0\ncomment voxcone generated mesh\nelement vertex "
      << mesh.positions.size() << "\nproperty float x\nproperty float y\nproperty float z\nelement face "
      << mesh.triangles.size() << "\nproperty list uchar int vertex_indices\nend_header\n";
    static_assert(sizeof(Vec3) == 12, "packed float positions");
    f.write(reinterpret_cast<const char*>(mesh.positions.data()), std::streamsize(mesh.positions.size() * sizeof(Vec3)));
    // Faces in chunks: a count byte and three little-endian int32 indices each.
    std::vector<char> buf;
    constexpr size_t kChunk = 1 << 16;
    for (size_t first = 0; first < mesh.triangles.size(); first += kChunk) {
      const size_t n = std::min(kChunk, mesh.triangles.size() - first);
      buf.resize(n * 13);
      for (size_t k = 0; k < n; ++k) {
        buf[k * 13] = 3;
        std::memcpy(&buf[k * 13 + 1], &mesh.triangles[first + k], 12);
      }
      f.write(buf.data(), std::streamsize(buf.size()));
    }
    f.close();
    if (!f) throw Error("cannot write " + tmp);
  });
}

}  // namespace voxcone

#pragma once
// Small scenes built in code for the tests.

#include "voxcone/photon/photon_tracer.h"
#include "voxcone/scene/scene.h"

#include <cmath>
#include <string>
#include <vector>

namespace voxcone::test {

/// Repository root (for data/ files).
inline std::string sourceDir() { return VOXCONE_SOURCE_DIR; }

/// A vector as a JSON array, for scene text written in a test.
inline std::string jsonVec(const Vec3& v) {
  return "[" + std::to_string(v.x) + ", " + std::to_string(v.y) + ", " + std::to_string(v.z) + "]";
}

/// A closed sphere (radius 1 at the origin, geodesic level `subdiv`) of one Lambertian
/// material with albedo `albedo`, emitting `emission` on both sides, seen by a camera at the
/// centre, plus optional point light at the centre with intensity `pointIntensity`.
inline Scene furnaceScene(float albedo, float emission, float pointIntensity, int subdiv = 4, int spp = 8,
                          int maxDepth = 256) {
  const std::string json = R"({
    "camera": {"position": [0, 0, 0], "target": [0, 0, 1], "up": [0, 1, 0], "fov_y_deg": 60},
    "render": {"width": 16, "height": 16, "spp": )" + std::to_string(spp) + R"(, "max_depth": )" +
                           std::to_string(maxDepth) + R"(},
    "materials": {"wall": {"type": "lambertian", "albedo": )" + std::to_string(albedo) +
                           R"(, "emission": )" + std::to_string(emission) + R"(, "two_sided_emission": true}},
    "shapes": [{"type": "sphere", "center": [0, 0, 0], "radius": 1, "subdivisions": )" +
                           std::to_string(subdiv) + R"(, "material": "wall"}],
    "lights": [)" + (pointIntensity > 0.0f ? R"({"type": "point", "position": [0, 0, 0], "intensity": )" +
                                                 std::to_string(pointIntensity) + "}"
                                           : std::string()) +
                           R"(]
  })";
  return parseScene(json, "furnace", ".");
}

/// Photon tracing settings: `photons` global and `caustic` caustic photons, the rest given.
inline PhotonSettings photonSettings(uint64_t photons, uint64_t caustic, int maxDepth = 16, uint64_t seed = 0) {
  PhotonSettings s;
  s.photons = photons;
  s.causticPhotons = caustic;
  s.maxDepth = maxDepth;
  s.seed = seed;
  return s;
}

/// Irradiance at p (unit normal n) from a polygon of unit radiance, fully above p's tangent
/// plane: Lambert's formula E = 1/2 sum_i Theta_i (n . Gamma_i), Theta_i the angle edge i
/// subtends at p and Gamma_i the unit normal of the plane through p and edge i (Arvo 1994,
/// "The Irradiance Jacobian for Partially Occluded Polyhedral Sources", eq. 1). In double.
inline double lambertPolygonIrradiance(const DVec3& p, const DVec3& n, const std::vector<DVec3>& polygon) {
  double sum = 0.0;
  for (size_t i = 0; i < polygon.size(); ++i) {
    const DVec3 a = polygon[i] - p, b = polygon[(i + 1) % polygon.size()] - p;
    const DVec3 c = glm::cross(a, b);
    const double theta = std::atan2(glm::length(c), glm::dot(a, b));
    sum += theta * glm::dot(n, c / glm::length(c));
  }
  return 0.5 * std::fabs(sum);
}

/// The six faces of the box [lo, hi] as JSON quads of `material`, their normals outward (or
/// inward, for a room).
inline std::string boxQuads(const Vec3& lo, const Vec3& hi, const std::string& material, bool inward) {
  std::string out;
  for (int axis = 0; axis < 3; ++axis)
    for (int side = 0; side < 2; ++side) {
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      Vec3 c[4];
      for (int k = 0; k < 4; ++k) {
        c[k][axis] = side ? hi[axis] : lo[axis];
        c[k][u] = (k == 1 || k == 2) ? hi[u] : lo[u];
        c[k][v] = (k >= 2) ? hi[v] : lo[v];
      }
      // (c0, c1, c2) winds to +axis (u x v); the outward normal of the low face is -axis.
      const bool reverse = (side == 0) != inward;
      if (!out.empty()) out += ",\n";
      out += R"({"type": "quad", "material": ")" + material + R"(", "vertices": [)";
      for (int k = 0; k < 4; ++k) out += (k ? ", " : "") + jsonVec(c[reverse ? 3 - k : k]);
      out += "]}";
    }
  return out;
}

/// A closed 2 m room (Lambertian 0.7) lit only by a 0.6 x 0.6 x 0.04 m lamp box (emission 10,
/// albedo 0.8) hanging `gap` under the ceiling, with a red block on the floor; the camera, at
/// `size` x `size` pixels, looks away from the lamp. The ceiling above the lamp is lit to many
/// times anything else and seen only through the gap. `lights`: the scene's lights beside the
/// lamp (a JSON list), outside the room.
inline Scene lampUnderCeilingScene(float gap, int size, int spp, const std::string& lights = "[]") {
  const std::string json = R"({
    "camera": {"position": [1, 1.1, 0.2], "target": [0.8, 1.2, 2], "up": [0, 1, 0], "fov_y_deg": 70},
    "render": {"width": )" + std::to_string(size) + R"(, "height": )" + std::to_string(size) + R"(, "spp": )" +
                           std::to_string(spp) + R"(, "max_depth": 16},
    "materials": {"wall": {"type": "lambertian", "albedo": 0.7}, "red": {"type": "lambertian", "albedo": [0.7, 0.2, 0.2]},
                  "lamp": {"type": "lambertian", "albedo": 0.8, "emission": 10}},
    "shapes": [)" + boxQuads(Vec3(0.0f), Vec3(2.0f), "wall", true) + ",\n" +
                           boxQuads(Vec3(0.7f, 2.0f - gap - 0.04f, 0.3f), Vec3(1.3f, 2.0f - gap, 0.9f), "lamp", false) +
                           ",\n" + boxQuads(Vec3(0.2f, 0.0f, 1.2f), Vec3(0.7f, 0.6f, 1.7f), "red", false) + R"(],
    "lights": )" + lights + R"(
  })";
  return parseScene(json, "lamp-under-ceiling", ".");
}

/// Solid angle of the rectangle [x0, x1] x [z0, z1] in the plane y = 0 seen from (0, h, 0):
/// the corner function atan(x z / (h sqrt(x^2 + z^2 + h^2))) summed with signs.
inline double rectangleSolidAngle(double x0, double x1, double z0, double z1, double h) {
  auto f = [h](double x, double z) { return std::atan(x * z / (h * std::sqrt(x * x + z * z + h * h))); };
  return f(x1, z1) - f(x0, z1) - f(x1, z0) + f(x0, z0);
}

}  // namespace voxcone::test

#pragma once
// Small scenes built in code for the tests.

#include "voxcone/photon/photon_tracer.h"
#include "voxcone/scene/scene.h"

#include <cmath>
#include <string>

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

/// Solid angle of the rectangle [x0, x1] x [z0, z1] in the plane y = 0 seen from (0, h, 0):
/// the corner function atan(x z / (h sqrt(x^2 + z^2 + h^2))) summed with signs.
inline double rectangleSolidAngle(double x0, double x1, double z0, double z1, double h) {
  auto f = [h](double x, double z) { return std::atan(x * z / (h * std::sqrt(x * x + z * z + h * h))); };
  return f(x1, z1) - f(x0, z1) - f(x1, z0) + f(x0, z0);
}

}  // namespace voxcone::test

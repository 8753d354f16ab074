#pragma once
// Small scenes built in code for the tests.

#include "voxcone/scene/scene.h"

#include <string>

namespace voxcone::test {

/// Repository root (for data/ files).
inline std::string sourceDir() { return VOXCONE_SOURCE_DIR; }

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

}  // namespace voxcone::test

// The coordinate range voxcone renders correctly in float (scene_loader.cpp, checkPrecision):
// cornell-box scaled and moved to the edges of the range renders what it renders at its own
// size; beyond them the scene is refused with an error that says why, never a wrong image.

#include "voxcone/core/error.h"
#include "voxcone/scene/scene.h"

#include "../support/render_helpers.h"
#include "../support/test_scenes.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <fstream>

namespace voxcone {
namespace {

/// cornell-box with every coordinate x replaced by x * scale + offset (radiance is unchanged
/// by scale and translation, so the image is too).
Scene transformedCornellBox(double scale, double offset) {
  std::ifstream f(test::sourceDir() + "/data/scenes/cornell-box.json");
  nlohmann::json j = nlohmann::json::parse(f);
  auto map = [&](nlohmann::json& v) {
    for (auto& c : v) c = c.get<double>() * scale + offset;
  };
  for (auto& shape : j["shapes"])
    if (shape.contains("vertices"))
      for (auto& v : shape["vertices"]) map(v);
  map(j["camera"]["position"]);
  map(j["camera"]["target"]);
  j["render"]["width"] = 16;
  j["render"]["height"] = 16;
  j["render"]["spp"] = 4;
  return parseScene(j.dump(), "cornell-box-transformed", test::sourceDir() + "/data/scenes");
}

double pathMean(const Scene& scene) {
  return test::renderWith(scene, "path", scene.render).image.mean();
}

TEST(Precision, CornellBoxAtTheEdgesOfTheRangeRendersAsAtItsOwnSize) {
  // cornell-box is 559 across: scales 2e-7 and 1.7e6 put it just inside [1e-4, 1e9], an
  // offset of 250 sides just inside the offset limit.
  const double own = pathMean(transformedCornellBox(1.0, 0.0));
  for (const auto& [scale, offset] : {std::pair{2e-7, 0.0}, std::pair{1.7e6, 0.0}, std::pair{1.0, 250.0 * 559.0}})
    EXPECT_NEAR(pathMean(transformedCornellBox(scale, offset)), own, 5e-3 * own) << scale << " " << offset;
}

TEST(Precision, ScenesBeyondTheRangeAreRefusedWithTheReason) {
  struct Case {
    double scale, offset;
    const char* expect;
  };
  // Measured before the check: scaled 1e7 the image mean was 0.07 instead of 0.12, 1e8 black;
  // 1e-8 1.4% off; moved 18,000 sides away 13% off; scaled 1e17 and 1e36 "up is parallel", 1e-40
  // "target equals position" (its float distances squared to zero).
  for (const Case& c : {Case{1e-7, 0.0, "units across"}, Case{1e7, 0.0, "units across"}, Case{1e8, 0.0, "units across"},
                        Case{1e-40, 0.0, "units across"}, Case{1.0, 1e7, "from the origin"},
                        Case{1e17, 0.0, "camera.position: coordinates beyond"},
                        Case{1e36, 0.0, "camera.position: coordinates beyond"}}) {
    try {
      transformedCornellBox(c.scale, c.offset);
      ADD_FAILURE() << "accepted scale " << c.scale << " offset " << c.offset;
    } catch (const SceneError& e) {
      EXPECT_NE(std::string(e.what()).find(c.expect), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace voxcone

// voxcone's defaults on the failure-case suite (data/scenes/failure, tools/make_failure_scenes.py):
// scenes of the kinds voxel methods fail on, none of them used to choose the defaults. Each is
// compared cell by cell (4 x 4) with path tracing at the scene's own 256 x 256.

#include "voxcone/accel/hbvh.h"
#include "voxcone/image/metrics.h"
#include "voxcone/integrator/integrator.h"

#include "../../support/render_helpers.h"
#include "../../support/test_scenes.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

namespace voxcone {
namespace {

using test::cellRatiosAgainstPath;
using test::imageMean;
using test::renderWith;

Scene failureScene(const std::string& name) {
  return loadScene(test::sourceDir() + "/data/scenes/failure/" + name + ".json");
}

/// The bound on a cell: the suite's target, 10% from converged path, plus two standard deviations
/// of path's own cell means at 64 spp (measured from two seeds at 128x128 and 256 spp, the same
/// samples per cell: at most 2.4% apart, a standard deviation of at most 1.7% each): 13%.
constexpr double kCellBound = 0.13;

void expectCellsNearPath(const std::string& name) {
  const std::vector<double> r = cellRatiosAgainstPath(failureScene(name));
  ASSERT_EQ(r.size(), 16u);
  double worst = 1.0;
  for (const double x : r) worst = std::fabs(x - 1.0) > std::fabs(worst - 1.0) ? x : worst;
  std::printf("%s: worst 4x4 cell %.3f of path (bound 1 +/- %.2f)\n", name.c_str(), worst, kCellBound);
  for (size_t i = 0; i < r.size(); ++i) EXPECT_NEAR(r[i], 1.0, kCellBound) << name << " cell " << i % 4 << ", " << i / 4;
}

TEST(FailureSuite, TwoRoomsWithADoorMatchPathInEveryCell) {
  // Measured against path at 4096 spp (256x256): worst cell 0.95, 42.3 dB. With the field's
  // voxels at the cones' hits (hit_radiance = field) the room beside the camera was lit through
  // the 5.5 mm wall: worst cell 1.33.
  expectCellsNearPath("two-rooms-door");
}

TEST(FailureSuite, AHallLitThroughARoofOpeningMatchesPathInEveryCell) {
  // Measured against path at 4096 spp: worst cell 1.08, 37.8 dB (hit_radiance = field: 0.68,
  // 29.7 dB, the far pillars and the columns' shadowed faces black).
  expectCellsNearPath("sunlit-hall");
}

TEST(FailureSuite, TheHallsPhotonsAreGuidedThroughTheRoofOpening) {
  // Under the hall's sun most photons land on the roof, where the camera never looks (the pilot:
  // 917 of 10,000 bounced photons in the seen cells). Unguided, the photon target needs the 2M
  // cap; guided by the pilot (grown to 179k photons) it needs about a fifth of that (measured
  // 393k) for as many photons where the camera looks. The image is held to path cell by cell by
  // the test above.
  const Scene hall = failureScene("sunlit-hall");
  const Hbvh accel(hall);
  nlohmann::json stats[2];
  for (int guided = 0; guided < 2; ++guided) {
    IntegratorContext ctx{hall, accel, hall.render, {{"photon_guide", guided ? 0.25 : 0.0}}};
    auto integrator = createIntegrator("voxcone", ctx);
    integrator->prepare(nullptr);
    stats[guided] = integrator->statsJson();
  }
  EXPECT_TRUE(stats[1]["photon_guide"]["used"].get<bool>());
  EXPECT_FALSE(stats[0].contains("photon_guide"));
  const double emitted[2] = {stats[0]["emitted_global"].get<double>(), stats[1]["emitted_global"].get<double>()};
  EXPECT_LT(emitted[1], 0.5 * emitted[0]);
  // The target (200k, asked for with 5% to spare) reached within 15% both ways: the guide's
  // expected share holds. Measured: 202k unguided; guided 230k, the expected share judged on
  // pilot photons the guide was not built on 0.535 against 0.585 achieved (judged on those it
  // was built on, the tree's promise was 16% too high: 176k).
  for (const nlohmann::json& s : stats) EXPECT_NEAR(s["seen_photons"].get<double>(), 210000.0, 31500.0);
}

TEST(FailureSuite, SixteenSmallColouredLightsMatchPathInEveryCell) {
  // Measured against path at 4096 spp (256x256): worst cell 1.029, 31.3 dB (with lights chosen
  // by power instead of the light tree: 28.0 dB).
  expectCellsNearPath("many-lights");
}

TEST(FailureSuite, AGlossyRoomWithAMirrorBallMatchesPathInEveryCell) {
  // Measured against path at 4096 spp (256x256): worst cell 0.936, 35.4 dB. With one randomly
  // aimed cone per glossy sample and no light seen in the mirror ball from the glossy wall and
  // floor (L S G), as the issue measured it on its version of the room: worst cell 0.72, 28.0 dB.
  expectCellsNearPath("glossy-room");
}

TEST(FailureSuite, SmallObjectsOnATableMatchPathInEveryCell) {
  // Measured against path at 4096 spp: worst cell 1.03, 39.2 dB.
  expectCellsNearPath("small-objects");
}

TEST(FailureSuite, ARoomLitThroughAWindowBySkyAndSunMatchesPathInEveryCell) {
  // Measured against path at 2048 spp (seed 7, 256x256): worst cell 0.964, 29.2 dB, with the sky
  // gathered by the cones (sky_light auto under a constant sky); by shadow rays 26.9 dB.
  expectCellsNearPath("sky-room");
}

/// A room no light path reaches renders exactly black in path and in voxcone at 64x64, 4 spp;
/// the field-read cones (hit_radiance = field) leak light into it: the failure the default
/// avoids, shown.
void expectClosedRoomBlack(const std::string& name) {
  const Scene closed = failureScene(name);
  RenderSettings s = closed.render;
  s.width = s.height = 64;
  s.spp = 4;
  EXPECT_EQ(imageMean(renderWith(closed, "path", s).image), Vec3(0.0f)) << name;
  EXPECT_EQ(imageMean(renderWith(closed, "voxcone", s).image), Vec3(0.0f)) << name;
  const Vec3 leak = imageMean(renderWith(closed, "voxcone", s, {{"hit_radiance", "field"}}).image);
  EXPECT_GT(leak.x, 0.0f) << name;
}

TEST(FailureSuite, TheRoomBehindAWalledUpWindowIsBlackUnderASky) {
  // The window filled with the wall's own 0.15 m: sky and sun light its outside only (the
  // field-read cones show 2% of the open room's light).
  expectClosedRoomBlack("sky-room-closed");
}

TEST(FailureSuite, TheRoomBehindAClosedDoorIsBlack) {
  // With the field's voxels at the cones' hits it showed 7.7% of the open room's mean.
  expectClosedRoomBlack("two-rooms-closed");
}

}  // namespace
}  // namespace voxcone

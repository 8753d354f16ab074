// voxcone's defaults on the failure-case suite (data/scenes/failure, tools/make_failure_scenes.py):
// scenes of the kinds voxel methods fail on, none of them used to choose the defaults. Each is
// compared cell by cell (4 x 4) with path tracing at the scene's own 256 x 256.

#include "voxcone/image/metrics.h"
#include "voxcone/integrator/integrator.h"

#include "../../support/render_helpers.h"
#include "../../support/test_scenes.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

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

TEST(FailureSuite, SmallObjectsOnATableMatchPathInEveryCell) {
  // Measured against path at 4096 spp: worst cell 1.03, 39.2 dB.
  expectCellsNearPath("small-objects");
}

TEST(FailureSuite, TheRoomBehindAClosedDoorIsBlack) {
  // No light path reaches the camera's room: path gives exactly 0 and so must voxcone (with the
  // field's voxels at the cones' hits it showed 7.7% of the open room's mean).
  const Scene closed = failureScene("two-rooms-closed");
  RenderSettings s = closed.render;
  s.width = s.height = 64;
  s.spp = 4;
  EXPECT_EQ(imageMean(renderWith(closed, "path", s).image), Vec3(0.0f));
  EXPECT_EQ(imageMean(renderWith(closed, "voxcone", s).image), Vec3(0.0f));
  // The field-read cones leak: the failure the default avoids, shown.
  const Vec3 leak = imageMean(renderWith(closed, "voxcone", s, {{"hit_radiance", "field"}}).image);
  EXPECT_GT(leak.x, 0.0f);
}

}  // namespace
}  // namespace voxcone

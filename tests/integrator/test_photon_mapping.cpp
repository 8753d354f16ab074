// Photon mapping ("pm"): furnace spheres, agreement with path tracing on the Cornell box,
// determinism across thread counts, option errors.

#include "voxcone/accel/hbvh.h"
#include "voxcone/core/error.h"
#include "voxcone/integrator/integrator.h"

#include "../support/render_helpers.h"
#include "../support/test_scenes.h"

#include <gtest/gtest.h>

namespace voxcone {
namespace {

using test::renderWith;

using test::cornellBox;
using test::imageMean;

TEST(PhotonMapping, PointLightFurnaceGivesOne) {
  // Kd = 0.5, I = pi at the centre of a unit sphere: direct 0.5 (shadow rays) plus indirect
  // 0.5 (global map, direct photons skipped), L = 1. On a sphere the Euclidean search ball cuts
  // a cap of area exactly pi r^2 (Archimedes), so the estimate's bias is the k/(k-1) of the
  // k-th photon on the rim (about 1% of the indirect half) plus noise.
  const Scene scene = test::furnaceScene(0.5f, 0.0f, kPi, 5, 2);
  for (int gather : {0, 8}) {
    const nlohmann::json options = {{"photons", 200000}, {"k", 100}, {"final_gather", gather}};
    const RenderResult r = renderWith(scene, "pm", scene.render, options);
    const Vec3 m = imageMean(r.image);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(m[c], 1.0, 0.02) << "final_gather " << gather;
    EXPECT_EQ(r.invalidSamples, 0u);
  }
}

TEST(PhotonMapping, EmissiveFurnaceGivesTwo) {
  // Albedo 0.5, Le = 1 everywhere: L = Le / (1 - a) = 2 = emission seen directly (1) + direct
  // light by shadow rays to the emissive triangles (0.5) + photons from the emitting walls
  // that bounced at least once (0.5).
  const Scene scene = test::furnaceScene(0.5f, 1.0f, 0.0f, 4, 2);
  const nlohmann::json options = {{"photons", 200000}, {"k", 100}};
  const RenderResult r = renderWith(scene, "pm", scene.render, options);
  const Vec3 m = imageMean(r.image);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(m[c], 2.0, 0.04);
}


TEST(PhotonMapping, CornellBoxMeanMatchesPath) {
  const test::CornellMeans m = test::cornellBoxMeans("pm", {{"photons", 200000}});
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(m.method[c], m.path[c], 0.05 * m.path[c]) << "channel " << c;
}

TEST(PhotonMapping, SameImageAtOneAndTwoThreads) {
  const Scene scene = cornellBox();
  RenderSettings s = scene.render;
  s.width = s.height = 40;  // not a multiple of the tile size
  s.spp = 2;
  for (int gather : {0, 4})
    EXPECT_EQ(test::pixelsDifferingAcrossThreads(scene, "pm", s, {{"photons", 50000}, {"final_gather", gather}}), 0u)
        << "final_gather " << gather;
}

TEST(PhotonMapping, BadOptionsAreSettingsErrors) {
  const Scene scene = cornellBox();
  const Hbvh accel(scene);
  IntegratorContext ctx{scene, accel, scene.render, nlohmann::json::object()};
  EXPECT_NO_THROW(createIntegrator("pm", ctx));
  for (const nlohmann::json& bad :
       {nlohmann::json{{"kk", 3}}, nlohmann::json{{"k", 0}}, nlohmann::json{{"k", 1.5}},
        nlohmann::json{{"max_radius", 0.0}}, nlohmann::json{{"max_radius", "big"}},
        nlohmann::json{{"final_gather", -1}}, nlohmann::json{{"photons", -5}}, nlohmann::json{{"seed", "x"}},
        nlohmann::json::array()}) {
    ctx.options = bad;
    EXPECT_THROW(createIntegrator("pm", ctx), SettingsError) << bad.dump();
  }
  ctx.options = {{"max_radius", 0.5}, {"k", 20}, {"final_gather", 4}, {"photons", 1000}, {"caustic_photons", 0},
                 {"seed", 3}};
  const auto pm = createIntegrator("pm", ctx);
  EXPECT_EQ(pm->name(), "pm");
  EXPECT_FLOAT_EQ(pm->settingsJson().at("max_radius").get<float>(), 0.5f);
  EXPECT_EQ(pm->settingsJson().at("k").get<int>(), 20);
}

}  // namespace
}  // namespace voxcone

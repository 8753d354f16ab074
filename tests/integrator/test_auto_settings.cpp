// render --target-error / --time-budget (auto_settings.h): the pilot's predictions against
// renders of the settings it chose, its choices against the request, bad requests.

#include "voxcone/accel/hbvh.h"
#include "voxcone/core/error.h"
#include "voxcone/image/metrics.h"
#include "voxcone/integrator/auto_settings.h"
#include "voxcone/integrator/integrator.h"

#include "../support/render_helpers.h"
#include "../support/temp_dir.h"
#include "../support/test_scenes.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>

namespace voxcone {
namespace {

/// The cornell-box, its HBVH and 48x48 voxcone settings: what every pilot test chooses for.
struct PilotScene {
  Scene scene = test::cornellBox();
  Hbvh accel{scene};
  RenderSettings settings = [this] {
    RenderSettings s = scene.render;
    s.width = s.height = 48;
    s.method = "voxcone";
    s.seed = 3;
    return s;
  }();
  AutoSettingsResult choose(const AutoSettingsRequest& req) const {
    return chooseVoxconeSettings(scene, accel, settings, req);
  }
};

Image renderChosen(const Scene& scene, const Accel& accel, RenderSettings s, const AutoSettingsResult& r,
                   uint64_t seed, int photonSeed) {
  s.spp = r.spp;
  s.seed = seed;
  nlohmann::json o = r.options;
  o["seed"] = photonSeed;
  IntegratorContext ctx{scene, accel, s, o};
  auto integrator = createIntegrator("voxcone", ctx);
  integrator->prepare(nullptr);
  return renderImage(scene, *integrator, s).image;
}

TEST(AutoSettings, PredictedNoiseMatchesRendersOfTheChosenSettings) {
  const PilotScene p;
  AutoSettingsRequest req;
  req.targetRelMse = 0.02;
  const AutoSettingsResult r = p.choose(req);
  ASSERT_TRUE(r.met);
  EXPECT_LE(r.predictedRelMse, 0.02);
  const nlohmann::json& terms = r.report["predicted_terms"];
  const double noise = terms["pixel_noise"].get<double>() + terms["photon_noise"].get<double>();
  EXPECT_NEAR(terms["pixel_noise"].get<double>() + terms["photon_noise"].get<double>() +
                  terms["level_bias"].get<double>() + terms["cone_bias"].get<double>(),
              r.predictedRelMse, 1e-12);
  // Two renders of the choice with other pixel and photon seeds than the pilot's: half their
  // relMSE is the noise the pilot predicted (its level and cone biases are the same in both).
  const Image a = renderChosen(p.scene, p.accel, p.settings, r, 101, 7);
  const Image b = renderChosen(p.scene, p.accel, p.settings, r, 202, 9);
  const double measured = relMseOfEstimates(a, b) / 2.0;
  EXPECT_GT(measured, noise / 2.0) << "predicted " << noise;
  EXPECT_LT(measured, noise * 2.0) << "predicted " << noise;
}

TEST(AutoSettings, TighterTargetsCostMoreAndFixedSettingsAreKept) {
  const PilotScene p;
  AutoSettingsRequest loose, tight;
  loose.targetRelMse = 0.05;
  tight.targetRelMse = 0.005;
  const AutoSettingsResult l = p.choose(loose);
  const AutoSettingsResult t = p.choose(tight);
  // Each choice runs its own pilot, and its time model is the pilot's own timing of small renders:
  // two pilots' predicted seconds differed by 12% and by 60% in CI at the defaults' tiny renders,
  // so they are not compared (that would be a timed test). What the targets decide does not
  // depend on the machine: each choice meets its own target.
  EXPECT_TRUE(l.met);
  EXPECT_TRUE(t.met);
  EXPECT_LE(l.predictedRelMse, loose.targetRelMse);
  EXPECT_LE(t.predictedRelMse, tight.targetRelMse);
  EXPECT_LE(l.spp, t.spp);
  EXPECT_LE(t.predictedRelMse, l.predictedRelMse);
  // A target no setting can meet: the most accurate is chosen and says so.
  AutoSettingsRequest impossible;
  impossible.targetRelMse = 1e-9;
  const AutoSettingsResult i = p.choose(impossible);
  EXPECT_FALSE(i.met);
  EXPECT_NE(i.summary.find("closest"), std::string::npos);
  // The user's own level and spp are not chosen.
  AutoSettingsRequest fixed = loose;
  fixed.fixedOptions = {{"level", 6}, {"exact_segment", 16}};
  fixed.fixedSpp = 2;
  const AutoSettingsResult f = p.choose(fixed);
  EXPECT_EQ(f.options["level"], 6);
  EXPECT_EQ(f.options["exact_segment"], 16);
  EXPECT_EQ(f.spp, 2);
  // A budget: the prediction fits what the pilot left of it.
  AutoSettingsRequest budget;
  budget.timeBudget = 30.0;
  const AutoSettingsResult b = p.choose(budget);
  ASSERT_TRUE(b.met);
  EXPECT_LE(b.predictedSeconds, 30.0 - b.pilotSeconds);
}

TEST(AutoSettings, BadRequestsAreErrors) {
  const PilotScene p;
  AutoSettingsRequest none, both;
  both.targetRelMse = 0.01;
  both.timeBudget = 10.0;
  EXPECT_THROW(p.choose(none), SettingsError);
  EXPECT_THROW(p.choose(both), SettingsError);
  AutoSettingsRequest badLevel;
  badLevel.targetRelMse = 0.01;
  badLevel.fixedOptions = {{"level", "six"}};
  EXPECT_THROW(p.choose(badLevel), SettingsError);
}

class AutoSettingsCli : public test::TempDirTest {};

TEST_F(AutoSettingsCli, RenderSaysWhatItChoseAndRecordsIt) {
  const std::string cli = VOXCONE_CLI_PATH;
  if (!std::filesystem::exists(cli)) GTEST_SKIP() << "no CLI at " << cli;
  const std::string scene = test::sourceDir() + "/data/scenes/cornell-box.json";
  ASSERT_EQ(std::system((cli + " render " + scene + " --res 32x32 --target-error 0.05 -q -o " + path("a") + " > " +
                         path("out.txt"))
                            .c_str()),
            0);
  std::ifstream out(path("out.txt"));
  const std::string text((std::istreambuf_iterator<char>(out)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("chose level"), std::string::npos) << text;
  EXPECT_NE(text.find("predicted relMSE"), std::string::npos) << text;
  std::ifstream f(path("a.json"));
  const nlohmann::json meta = nlohmann::json::parse(f);
  EXPECT_EQ(meta["method"], "voxcone");
  EXPECT_EQ(meta["settings"]["spp"], meta["auto"]["chosen"]["spp"]);
  EXPECT_EQ(meta["settings"]["integrator"]["level"], meta["auto"]["chosen"]["level"]);
  EXPECT_GT(meta["timings"]["pilot_seconds"].get<double>(), 0.0);
  // Another method has nothing to choose; both flags at once is an error too. Nothing written.
  EXPECT_NE(std::system((cli + " render " + scene + " --method path --target-error 0.05 -q -o " + path("b") +
                         " > /dev/null 2>&1")
                            .c_str()),
            0);
  EXPECT_NE(std::system((cli + " render " + scene + " --res 32x32 --target-error 0.05 --time-budget 5 -q -o " +
                         path("c") + " > /dev/null 2>&1")
                            .c_str()),
            0);
  EXPECT_FALSE(std::filesystem::exists(path("b.json")));
  EXPECT_FALSE(std::filesystem::exists(path("c.json")));
}

}  // namespace
}  // namespace voxcone

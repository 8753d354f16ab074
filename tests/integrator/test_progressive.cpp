// render --target-error / --time-budget (progressive.h): the passes' noise estimate against
// independent renders, the control pixels' bias estimate against a bias known from converged
// images, determinism, the request's errors, and the CLI.

#include "voxcone/accel/hbvh.h"
#include "voxcone/core/error.h"
#include "voxcone/core/parallel.h"
#include "voxcone/image/metrics.h"
#include "voxcone/integrator/progressive.h"
#include "voxcone/integrator/integrator.h"

#include "../support/render_helpers.h"
#include "../support/temp_dir.h"
#include "../support/test_scenes.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>

#include <sys/wait.h>

namespace voxcone {
namespace {

/// The cornell-box, its HBVH and 64x64 voxcone settings (64 control pixels).
struct ProgressiveScene {
  Scene scene = test::cornellBox();
  Hbvh accel{scene};
  RenderSettings settings = [this] {
    RenderSettings s = scene.render;
    s.width = s.height = 64;
    s.method = "voxcone";
    s.seed = 3;
    return s;
  }();
  ProgressiveResult run(const ProgressiveRequest& req) const { return renderVoxconeToTarget(scene, accel, settings, req); }
};

TEST(Progressive, NoiseEstimateMatchesIndependentRendersAndTheImageIsThePassesMean) {
  const ProgressiveScene p;
  ProgressiveRequest req;
  req.targetRelMse = 0.02;
  req.maxPasses = 6;
  const ProgressiveResult r = p.run(req);
  ASSERT_GE(r.passes, 2);
  EXPECT_EQ(r.result.samples, uint64_t(r.passes) * 64 * 64 * 4);
  EXPECT_DOUBLE_EQ(r.predictedRelMse, r.noise / r.passes + r.bias2);
  EXPECT_TRUE(r.met);
  EXPECT_LE(r.predictedRelMse, 0.02);
  // voxcone's own bias is small (relMSE about 6e-4 at 256x256): the estimate, after the
  // variances of both means are taken off, is small too (left in, they add 0.01 or more here).
  const double bias2Raw = r.report["bias2_raw"].get<double>();
  EXPECT_LT(std::abs(bias2Raw), 0.003) << r.report.dump();
  // Two plain renders at other seeds: half their relMSE is one pass's noise.
  RenderSettings s = p.settings;
  s.spp = 4;
  Image img[2];
  for (int i = 0; i < 2; ++i) {
    s.seed = 100 + uint64_t(i);
    img[i] = test::renderWith(p.scene, "voxcone", s).image;
  }
  const double measured = relMseOfEstimates(img[0], img[1]) / 2.0;
  EXPECT_GT(r.noise, measured / 1.5);
  EXPECT_LT(r.noise, measured * 1.5);
  // Pass k is the render at seed + k (photons traced into kept voxels are the same as a fresh
  // prepare's): with two passes the image is the mean of the renders at seeds 3 and 4.
  req.maxPasses = 2;
  const ProgressiveResult two = p.run(req);
  ASSERT_EQ(two.passes, 2);
  for (int i = 0; i < 2; ++i) {
    s.seed = 3 + uint64_t(i);
    img[i] = test::renderWith(p.scene, "voxcone", s).image;
  }
  double maxDiff = 0.0;
  for (size_t q = 0; q < img[0].pixels.size(); ++q)
    for (int c = 0; c < 3; ++c)
      maxDiff = std::max(maxDiff, std::abs(double(two.result.image.pixels[q][c]) -
                                           0.5 * (double(img[0].pixels[q][c]) + double(img[1].pixels[q][c]))));
  EXPECT_LT(maxDiff, 1e-6);
}

TEST(Progressive, BiasEstimateMatchesAKnownBias) {
  // voxcone's direct light alone (view "direct") lacks the indirect light: a large bias, known
  // from converged images (direct at 256 spp against path at 1024 spp, relMSE with the same
  // epsilon). The control pixels' estimate must find it; without subtracting the variances it
  // would be too high, with the spread of stratified path samples negative.
  const ProgressiveScene p;
  ProgressiveRequest req;
  req.timeBudget = 1e6;  // stopped by maxPasses
  req.maxPasses = 4;
  req.options = {{"view", "direct"}};
  const ProgressiveResult r = p.run(req);
  RenderSettings s = p.settings;
  s.spp = 256;
  const Image direct = test::renderWith(p.scene, "voxcone", s, {{"view", "direct"}}).image;
  s.spp = 1024;
  const Image path = test::renderWith(p.scene, "path", s).image;
  double truth = 0.0;
  for (size_t q = 0; q < direct.pixels.size(); ++q)
    for (int c = 0; c < 3; ++c) {
      const double d = direct.pixels[q][c], t = path.pixels[q][c];
      truth += (d - t) * (d - t) / (d * d + kRelMseEpsilon);
    }
  truth /= double(direct.pixels.size() * 3);
  ASSERT_GT(truth, 0.05);
  // 64 control pixels sample the image's bias: about 20% of spatial sampling error.
  EXPECT_NEAR(r.bias2, truth, 0.3 * truth) << "standard error " << r.report["bias2_standard_error"];
}

TEST(Progressive, SameImageAtOneAndTwoThreadsAndBadRequestsAreErrors) {
  const ProgressiveScene p;
  ProgressiveRequest req;
  req.targetRelMse = 0.05;
  Image img[2];
  for (int threads : {1, 2}) {
    ThreadLimit limit(threads);
    img[threads - 1] = p.run(req).result.image;
  }
  EXPECT_EQ(img[0].pixels, img[1].pixels);

  ProgressiveRequest none, both, impossible, badSpp;
  both.targetRelMse = 0.01;
  both.timeBudget = 10.0;
  EXPECT_THROW(p.run(none), SettingsError);
  EXPECT_THROW(p.run(both), SettingsError);
  badSpp.targetRelMse = 0.01;
  badSpp.passSpp = 0;
  EXPECT_THROW(p.run(badSpp), SettingsError);
  // Far below voxcone's bias: refused once the bias is known, not rendered for ever.
  impossible.targetRelMse = 1e-9;
  try {
    p.run(impossible);
    ADD_FAILURE() << "a target below the bias was accepted";
  } catch (const SettingsError& e) {
    EXPECT_NE(std::string(e.what()).find("bias"), std::string::npos) << e.what();
  }
}

class AutoSettingsCli : public test::TempDirTest {};

TEST_F(AutoSettingsCli, RenderSaysWhatItDidAndRecordsIt) {
  const std::string cli = VOXCONE_CLI_PATH;
  if (!std::filesystem::exists(cli)) GTEST_SKIP() << "no CLI at " << cli;
  const std::string scene = test::sourceDir() + "/data/scenes/cornell-box.json";
  ASSERT_EQ(std::system((cli + " render " + scene + " --res 32x32 --target-error 0.05 -o " + path("a") + " > " +
                         path("out.txt"))
                            .c_str()),
            0);
  std::ifstream out(path("out.txt"));
  const std::string text((std::istreambuf_iterator<char>(out)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("passes of 4 spp"), std::string::npos) << text;
  EXPECT_NE(text.find("predicted relMSE"), std::string::npos) << text;
  std::ifstream f(path("a.json"));
  const nlohmann::json meta = nlohmann::json::parse(f);
  EXPECT_EQ(meta["method"], "voxcone");
  EXPECT_EQ(meta["settings"]["spp"], meta["auto"]["chosen"]["spp"]);
  EXPECT_EQ(meta["auto"]["chosen"]["spp"], meta["auto"]["chosen"]["passes"].get<int>() * 4);
  EXPECT_GT(meta["timings"]["pilot_seconds"].get<double>(), 0.0);
  // Another method has nothing to choose; both flags at once and an unreachable target are
  // errors too. Nothing written.
  EXPECT_NE(std::system((cli + " render " + scene + " --method path --target-error 0.05 -q -o " + path("b") +
                         " > /dev/null 2>&1")
                            .c_str()),
            0);
  EXPECT_NE(std::system((cli + " render " + scene + " --res 32x32 --target-error 0.05 --time-budget 5 -q -o " +
                         path("c") + " > /dev/null 2>&1")
                            .c_str()),
            0);
  EXPECT_NE(std::system((cli + " render " + scene + " --res 32x32 --target-error 1e-9 -q -o " + path("d") +
                         " > /dev/null 2>&1")
                            .c_str()),
            0);
  for (const char* name : {"b.json", "c.json", "d.json", "d.exr"}) EXPECT_FALSE(std::filesystem::exists(path(name))) << name;
  // A budget the two passes overrun: the image is written, and the exit code (3) says the
  // budget was not met.
  const int status = std::system((cli + " render " + scene + " --res 32x32 --time-budget 0.001 -q -o " + path("e") +
                                  " > /dev/null 2>&1")
                                     .c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 3);
  EXPECT_TRUE(std::filesystem::exists(path("e.exr")));
  std::ifstream e(path("e.json"));
  EXPECT_FALSE(nlohmann::json::parse(e)["auto"]["met"].get<bool>());
}

}  // namespace
}  // namespace voxcone

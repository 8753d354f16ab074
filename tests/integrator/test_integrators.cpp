// Analytic scenes over the integrators (pbrt-v4's integrators_test.cpp): furnace spheres, the
// Cornell box's orientation and seed-to-seed agreement, determinism across thread counts.

#include "voxcone/accel/hbvh.h"
#include "voxcone/core/error.h"
#include "voxcone/integrator/integrator.h"

#include "../support/render_helpers.h"
#include "../support/test_scenes.h"

#include <gtest/gtest.h>

namespace voxcone {
namespace {

using test::renderWith;

/// Mean and standard error of the pixel means of one channel.
std::pair<double, double> meanAndStdErr(const Image& img, int channel) {
  double s = 0.0, s2 = 0.0;
  for (const Vec3& p : img.pixels) {
    s += p[channel];
    s2 += double(p[channel]) * p[channel];
  }
  const double n = double(img.pixels.size());
  const double mean = s / n;
  return {mean, std::sqrt(std::max(0.0, s2 / n - mean * mean) / n)};
}

TEST(Furnace, PathEmissiveDiffuseSphereGivesOneOverOneMinusAlbedo) {
  // Inside a closed sphere of albedo a emitting Le everywhere, L = Le + a L, so L = Le / (1-a).
  // Sample counts keep the standard error of the image mean at about 0.25% (measured pixel
  // std. dev. 0.19 at 256 spp for a = 0.8), so the 1% bound is four standard errors.
  for (float a : {0.5f, 0.8f}) {
    const Scene scene = test::furnaceScene(a, 1.0f, 0.0f, 3, a == 0.5f ? 64 : 256);
    const RenderResult r = renderWith(scene, "path", scene.render);
    const double expected = 1.0 / (1.0 - a);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(meanAndStdErr(r.image, c).first, expected, 0.01 * expected) << "albedo " << a;
    EXPECT_EQ(r.invalidSamples, 0u);
  }
}

TEST(Furnace, PathPointLightAtCentreOfLambertianSphereGivesOne) {
  // Kd = 0.5, I = pi, r = 1: direct L = Kd/pi * I/r^2 = 0.5; interreflection in a sphere is
  // uniform, so L = 0.5 / (1 - 0.5) = 1. The geodesic sphere (level 5) sits slightly inside the
  // unit sphere, which raises E by about 0.1%.
  const Scene scene = test::furnaceScene(0.5f, 0.0f, kPi, 5, 16);
  const RenderResult r = renderWith(scene, "path", scene.render);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(meanAndStdErr(r.image, c).first, 1.0, 0.01);
}

TEST(Furnace, WhittedPointLightGivesDirectLightOnly) {
  // Whitted has no diffuse interreflection: only the direct 0.5 of the test above.
  const Scene scene = test::furnaceScene(0.5f, 0.0f, kPi, 5, 4);
  const RenderResult r = renderWith(scene, "whitted", scene.render);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(meanAndStdErr(r.image, c).first, 0.5, 0.005);
}

using test::cornellBox;

TEST(CornellBox, RedWallIsOnTheLeft) {
  const Scene scene = cornellBox();
  RenderSettings s = scene.render;
  s.width = s.height = 32;
  s.spp = 8;
  const Image img = renderWith(scene, "path", s).image;
  // Columns 1-2 see the red wall, columns 29-30 the green wall (rows in the middle).
  Vec3 left(0.0f), right(0.0f);
  for (int y = 8; y < 24; ++y) {
    left += img.at(1, y) + img.at(2, y);
    right += img.at(29, y) + img.at(30, y);
  }
  EXPECT_GT(left.x, 3.0f * left.y);
  EXPECT_GT(left.x, 3.0f * left.z);
  EXPECT_GT(right.y, 1.5f * right.x);
  EXPECT_GT(right.y, 1.5f * right.z);
}

TEST(CornellBox, PathAtTwoSeedsAgreesWithinNoise) {
  const Scene scene = cornellBox();
  RenderSettings s = scene.render;
  s.width = s.height = 32;
  s.spp = 16;
  s.seed = 1;
  const Image a = renderWith(scene, "path", s).image;
  s.seed = 2;
  const Image b = renderWith(scene, "path", s).image;
  EXPECT_NE(a.pixels[500].x, b.pixels[500].x);  // really different samples
  for (int c = 0; c < 3; ++c) {
    const auto [ma, ea] = meanAndStdErr(a, c);
    const auto [mb, eb] = meanAndStdErr(b, c);
    // Image means agree within 4 standard errors of their difference. The pixel spread
    // includes the image's structure, so this bound is conservative in the right direction.
    EXPECT_NEAR(ma, mb, 4.0 * std::sqrt(ea * ea + eb * eb)) << "channel " << c;
    EXPECT_GT(ma, 0.02);  // the light (17, 12, 4) is dim in blue: the blue mean is about 0.036
  }
}

TEST(Determinism, SameImageAtOneAndTwoThreads) {
  const Scene scene = cornellBox();
  RenderSettings s = scene.render;
  s.width = s.height = 40;  // not a multiple of the tile size
  s.spp = 4;
  for (const std::string method : {"path", "whitted"})
    EXPECT_EQ(test::pixelsDifferingAcrossThreads(scene, method, s), 0u) << method;
}

TEST(Integrators, UnknownMethodAndOptionsAreErrors) {
  const Scene scene = cornellBox();
  const Hbvh accel(scene);
  IntegratorContext ctx{scene, accel, scene.render, nlohmann::json::object()};
  EXPECT_THROW(createIntegrator("nope", ctx), SettingsError);
  ctx.options = {{"rr_dept", 3}};
  EXPECT_THROW(createIntegrator("path", ctx), SettingsError);
  ctx.options = {{"rr_depth", -1}};
  EXPECT_THROW(createIntegrator("path", ctx), SettingsError);
  RenderSettings bad = scene.render;
  bad.spp = 0;
  EXPECT_THROW(bad.validate(), SettingsError);
}

}  // namespace
}  // namespace voxcone

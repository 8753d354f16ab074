// voxcone's split of the light that leaves surfaces beside a lamp (near_light, LightProximity):
// the photons record it, the image does not depend on the split's radius (every radius is the
// same light, divided differently between the cones and the photons), and a lamp 2 cm under a
// ceiling no longer throws single cones a hundred times the light their solid angle receives.

#include "voxcone/accel/hbvh.h"
#include "voxcone/photon/light_proximity.h"
#include "voxcone/photon/photon_tracer.h"

#include "../../support/render_helpers.h"
#include "../../support/report.h"
#include "../../support/test_scenes.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>

namespace voxcone {
namespace {

using test::lampUnderCeilingScene;
using test::luminance;
using test::renderWith;
using test::report;

/// Luminance ratios of the 4 x 4 cells of `test` to `reference`.
std::vector<double> cellRatios(const Image& test, const Image& reference) {
  std::vector<double> r;
  for (const RegionError& c : regionErrors(test, reference, 4)) r.push_back(luminance(c.meanTest) / luminance(c.meanReference));
  return r;
}

double worstDeviation(const std::vector<double>& ratios) {
  double worst = 0.0;
  for (double r : ratios) worst = std::max(worst, std::abs(r - 1.0));
  return worst;
}

TEST(NearLight, PhotonsRecordTheNearShareOfTheLastSurfaceTheyLeft) {
  const Scene scene = lampUnderCeilingScene(0.02f, 16, 1);
  const Hbvh accel(scene);
  PhotonSettings s = test::photonSettings(20000, 0);
  const PhotonMaps plain = tracePhotons(scene, accel, s);
  for (const Photon& p : plain.global) ASSERT_EQ(p.nearShare, 0.0f);
  s.proximity = std::make_shared<LightProximity>(scene, 0.3f);
  const PhotonMaps maps = tracePhotons(scene, accel, s);
  // The same photons: the proximity changes what they record, not where they go.
  ASSERT_EQ(maps.global.size(), plain.global.size());
  size_t near = 0, full = 0;
  for (size_t i = 0; i < maps.global.size(); ++i) {
    const Photon& p = maps.global[i];
    ASSERT_EQ(p.position, plain.global[i].position);
    ASSERT_GE(p.nearShare, 0.0f);
    ASSERT_LE(p.nearShare, 1.0f);
    // Straight from the lamp: no surface left yet.
    if (p.bounces == 0) {
      ASSERT_EQ(p.nearShare, 0.0f);
    }
    near += p.nearShare > 0.0f ? 1 : 0;
    full += p.nearShare == 1.0f ? 1 : 0;
  }
  // Photons bounce off the lamp itself (share 1) and the ceiling above it, and most of the room
  // lies beyond 0.3 m of the lamp.
  report("photons of share 1 (lower bound)", double(full), 100.0);
  report("photons of share > 0", double(near), double(maps.global.size() / 2));
  EXPECT_GT(full, 100u);
  EXPECT_GT(near, full);
  EXPECT_LT(near, maps.global.size() / 2);
}

/// voxcone's image of the lamp room at `nearLight` (< 0: the default) and `seed`.
Image lampRoom(double nearLight, uint64_t seed, int size = 48, int hitLightSamples = 0) {
  const Scene scene = lampUnderCeilingScene(0.02f, size, 16);
  RenderSettings s = scene.render;
  s.seed = seed;
  nlohmann::json options = nlohmann::json::object();
  if (nearLight >= 0.0) options["near_light"] = nearLight;
  if (hitLightSamples > 0) options["hit_light_samples"] = hitLightSamples;
  return renderWith(scene, "voxcone", s, options).image;
}

TEST(NearLight, AFurnaceOfLampsGivesTwoFromThePhotonsAlone) {
  // A closed sphere whose every point emits 1 with albedo 0.5: L = 2 everywhere. Every surface is
  // a lamp, so the cones take none of the light that bounced and the photons at the gathering
  // points all of it. One estimate per gathering pixel (k = 32: about 20% apart from point to
  // point) is what the image averages: 64x64 pixels, 256 gathering ones. Measured 1.995 and
  // 2.003.
  const Scene scene = test::furnaceScene(0.5f, 1.0f, 0.0f, 4, 2);
  RenderSettings s = scene.render;
  s.width = s.height = 64;
  for (const uint64_t seed : {1u, 2u}) {
    s.seed = seed;
    const RenderResult r = renderWith(scene, "voxcone", s, {{"photons", 100000}});
    const Vec3 m = test::imageMean(r.image);
    int worst = 0;  // the channel furthest from 2
    for (int c = 1; c < 3; ++c)
      if (std::fabs(m[c] - 2.0) > std::fabs(m[worst] - 2.0)) worst = c;
    report("seed " + std::to_string(seed) + " mean - 2, worst channel (bound on |x|)", m[worst] - 2.0, 0.02);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(m[c], 2.0, 0.02) << "seed " << seed;
  }
}

/// The mean of lampRoom(nearLight, seed) over seeds 1-3.
Image lampRoomOverSeeds(double nearLight) {
  Image sum = lampRoom(nearLight, 1);
  for (const uint64_t seed : {2u, 3u}) {
    const Image more = lampRoom(nearLight, seed);
    for (int y = 0; y < sum.height; ++y)
      for (int x = 0; x < sum.width; ++x) sum.at(x, y) += more.at(x, y);
  }
  for (int y = 0; y < sum.height; ++y)
    for (int x = 0; x < sum.width; ++x) sum.at(x, y) /= 3.0f;
  return sum;
}

TEST(NearLight, TheImageDoesNotDependOnTheSplitsRadius) {
  // 0.15 m, 0.6 m and 100 m (every surface within it: the cones take nothing and the photons
  // at the gathering points all that bounced) divide the same light differently. One seed is
  // not enough to tell: at 100 m a cell moves by a standard deviation of 0.05-0.08 of its mean
  // from seed to seed (9 seeds against path; at 0.6 m by up to 0.052, the next test), so one
  // render of each was 0.055-0.133 apart at seed 1 as the photon count moved by 7%. Over seeds
  // 1-3 measured: the worst cells 0.024-0.029 apart at 100 m; the means within 2%.
  const Image a = lampRoomOverSeeds(0.15), b = lampRoomOverSeeds(0.6), c = lampRoomOverSeeds(100.0);
  const double ma = luminance(DVec3(test::imageMean(a))), mb = luminance(DVec3(test::imageMean(b))),
               mc = luminance(DVec3(test::imageMean(c)));
  report("|mean 0.15 m / mean 0.6 m - 1|", std::fabs(ma / mb - 1.0), 0.02);
  report("|mean 100 m / mean 0.6 m - 1|", std::fabs(mc / mb - 1.0), 0.02);
  report("worst cell 0.15 m vs 0.6 m", worstDeviation(cellRatios(a, b)), 0.07);
  report("worst cell 100 m vs 0.6 m", worstDeviation(cellRatios(c, b)), 0.07);
  EXPECT_NEAR(ma / mb, 1.0, 0.02);
  EXPECT_NEAR(mc / mb, 1.0, 0.02);
  EXPECT_LT(worstDeviation(cellRatios(a, b)), 0.07);
  EXPECT_LT(worstDeviation(cellRatios(c, b)), 0.07);
}

// Measured (48x48, 16 spp, path at 1024 spp; path's own image mean moves by 0.2% from seed to
// seed at 1024 spp, against 8192): the default's image mean 1.018 of path, worst cell 0.057,
// cells of two seeds at most 0.030 apart (with one shadow ray at a cone's hit, 0.035); with
// near_light 0 and one shadow ray, worst cell 0.085 and 0.092 apart from seed to seed (one cone
// in thousands meets the ceiling above the lamp). The 3% is, as far
// as we can tell, the photon estimate's blur where the gathering points take the light from
// beside the lamp: the light that leaves the 2 cm gap lands in strips that the estimate's disc
// (up to hit_radius, 0.17 m here) spreads. Before those estimates were fitted at edges
// (edge_fit: off): the mean 1.029, worst cell 0.078, seeds 0.052 apart.
TEST(NearLight, ALampUnderTheCeilingMatchesPathAndNoCellMovesWithTheSeed) {
  const Scene scene = lampUnderCeilingScene(0.02f, 48, 16);
  RenderSettings p = scene.render;
  p.spp = 1024;
  p.seed = 99;
  const Image path = renderWith(scene, "path", p).image;
  const Image s1 = lampRoom(-1.0, 1), s2 = lampRoom(-1.0, 2);
  const double vsPath = worstDeviation(cellRatios(s1, path)), seeds = worstDeviation(cellRatios(s1, s2));
  const double mean = luminance(DVec3(test::imageMean(s1))) / luminance(DVec3(test::imageMean(path)));
  // The split's own effect, with one shadow ray at each cone's hit (the default's 4 also cut the
  // light the rare cone above the lamp brings: near_light 0 is then 0.041 apart, against 0.030).
  const Image n1 = lampRoom(-1.0, 1, 48, 1), n2 = lampRoom(-1.0, 2, 48, 1);
  const Image o1 = lampRoom(0.0, 1, 48, 1), o2 = lampRoom(0.0, 2, 48, 1);
  const double seedsOne = worstDeviation(cellRatios(n1, n2)), seedsOff = worstDeviation(cellRatios(o1, o2)),
               offVsPath = worstDeviation(cellRatios(o1, path));
  report("mean / path's - 1 (bound on |x|)", mean - 1.0, 0.04);
  report("worst cell vs path", vsPath, 0.10);
  report("worst cell seed 1 vs seed 2", seeds, 0.08);
  report("1 shadow ray at a hit: worst cell seed 1 vs seed 2", seedsOne);
  report("1 shadow ray, near_light 0: worst cell seed 1 vs seed 2 (lower bound 1.5x near_light's)", seedsOff,
         1.5 * seedsOne);
  report("1 shadow ray, near_light 0: worst cell vs path", offVsPath);
  EXPECT_NEAR(mean, 1.0, 0.04);
  EXPECT_LT(vsPath, 0.10);
  EXPECT_LT(seeds, 0.08);
  // Without the split the seeds disagree by twice as much (the failure this guards).
  EXPECT_GT(seedsOff, 1.5 * seedsOne);
}

// The lamp room, closed, under a bright sky outside: by power the sky takes all but 0.5% of the
// photons (10.8k of the main pass's 2M), and none of its light gets in, so the room's light is
// the lamp's alone, as without the sky. The lamp pass (190k photons) and the main pass's lamp
// photons each weigh in by their share; near_light 1.5 m gives the photons at the gathering
// points most of the light that bounced, so a wrong weight shows (leaving the pass's photons at
// full weight: mean 1.031, worst cell 0.096, at seed 1). Measured over seeds 1-3 (the pass
// 190k photons): mean 0.997 of the sky-less room's, worst cell 0.041; without the pass 0.022
// (here the main pass's 10.8k lamp photons do as well: at seed 1 alone 0.056 against 0.046-0.078
// with passes of 90k-390k photons; the rooms of tools/make_gltf_room.py are where it pays).

TEST(NearLight, ALampStarvedByASkyGetsAPassOfItsOwn) {
  const Scene plain = lampUnderCeilingScene(0.02f, 48, 16);
  const Scene sky = lampUnderCeilingScene(0.02f, 48, 16, R"([{"type": "environment", "radiance": 40}])");
  // The mean image of seeds 1-3 (a cell of one seed's is known to about 3%: the worst of 16 cells
  // between two such images moved between 0.046 and 0.078 with the pass's photon count).
  const auto render = [&](const Scene& scene, const nlohmann::json& options, nlohmann::json* stats) {
    const Hbvh accel(scene);
    Image sum;
    for (const uint64_t seed : {1u, 2u, 3u}) {
      RenderSettings s = plain.render;
      s.seed = seed;
      s.method = "voxcone";
      auto integrator = createIntegrator("voxcone", IntegratorContext{scene, accel, s, options});
      integrator->prepare(nullptr);
      if (stats && seed == 1u) *stats = integrator->statsJson();
      const Image img = renderImage(scene, *integrator, s).image;
      if (sum.pixels.empty()) sum = img;
      else
        for (size_t p = 0; p < sum.pixels.size(); ++p) sum.pixels[p] += img.pixels[p];
    }
    for (Vec3& v : sum.pixels) v /= 3.0f;
    return sum;
  };
  nlohmann::json stats;
  const nlohmann::json wide = {{"near_light", 1.5}};
  const Image reference = render(plain, wide, nullptr);
  const Image withPass = render(sky, wide, &stats);
  const Image without = render(sky, {{"near_light", 1.5}, {"lamp_photons", 0}}, nullptr);
  ASSERT_TRUE(stats["near_light"].contains("lamp_pass")) << stats.dump();
  const double mean = luminance(DVec3(test::imageMean(withPass))) / luminance(DVec3(test::imageMean(reference)));
  const double worst = worstDeviation(cellRatios(withPass, reference)),
               worstWithout = worstDeviation(cellRatios(without, reference));
  std::printf("lamp pass %s\n", stats["near_light"]["lamp_pass"].dump().c_str());
  report("mean / the sky-less room's - 1 (bound on |x|)", mean - 1.0, 0.025);
  report("worst cell vs the sky-less room", worst, 0.06);
  report("without the pass: worst cell", worstWithout);
  EXPECT_NEAR(mean, 1.0, 0.025);
  EXPECT_LT(worst, 0.06);
}

}  // namespace
}  // namespace voxcone

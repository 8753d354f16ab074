// The emission guide against hand-computed values and against closed forms: its density in
// primary sample space, its weights (an integral over [0,1)^3 is unchanged under guiding), and
// photons guided to a patch under a point light carrying the flux I Omega as unguided ones do.
//
// Statistical bounds are 5 standard deviations of the estimator in question (derived, or
// estimated from the samples themselves), so a failure means a bias, not bad luck.

#include "voxcone/photon/emission_guide.h"

#include "voxcone/accel/hbvh.h"
#include "voxcone/core/error.h"
#include "voxcone/core/rng.h"
#include "voxcone/photon/photon_tracer.h"
#include "voxcone/scene/scene.h"

#include "../support/test_scenes.h"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>

namespace voxcone {
namespace {

using test::rectangleSolidAngle;

TEST(EmissionGuide, UniformGuideNamesBinsAndChangesNothing) {
  const EmissionGuide g(2, 4);
  EXPECT_EQ(g.bins(), 32);
  EXPECT_TRUE(g.uniform());
  // Bin = (slice * dirRes + row) * dirRes + column, row from uDir.y.
  EXPECT_EQ(g.binOf(0.0, Vec2(0.0f, 0.0f)), 0);
  EXPECT_EQ(g.binOf(0.49, Vec2(0.3f, 0.0f)), 1);
  EXPECT_EQ(g.binOf(0.49, Vec2(0.0f, 0.3f)), 4);
  EXPECT_EQ(g.binOf(0.5, Vec2(0.99f, 0.99f)), 16 + 15);
  EXPECT_EQ(g.binOf(0.999999, Vec2(0.9999999f, 0.9999999f)), 31);
  double uLight = 0.37;
  Vec2 uDir(0.12f, 0.93f);
  EXPECT_EQ(g.remap(uLight, uDir), 1.0);
  EXPECT_EQ(uLight, 0.37);
  EXPECT_EQ(uDir, Vec2(0.12f, 0.93f));
  EXPECT_DOUBLE_EQ(g.pmf(5), 1.0 / 32.0);
}

TEST(EmissionGuide, BadLayoutsAndCountsAreRefused) {
  EXPECT_THROW(EmissionGuide(3, 4), Error);
  EXPECT_THROW(EmissionGuide(1, 0), Error);
  EXPECT_THROW(EmissionGuide(1, 2048), Error);
  EXPECT_THROW(EmissionGuide::fromUseful(1, 2, {1, 2, 3}, 0.25), Error);
  EXPECT_THROW(EmissionGuide::fromUseful(1, 2, {1, 2, 3, -1}, 0.25), Error);
  EXPECT_THROW(EmissionGuide::fromUseful(1, 2, {1, 2, 3, NAN}, 0.25), Error);
  EXPECT_THROW(EmissionGuide::fromUseful(1, 2, {1, 2, 3, 4}, 0.0), Error);
  EXPECT_THROW(EmissionGuide::aggregate({1, 2, 3, 4}, 1, 2, 1, 3), Error);
}

TEST(EmissionGuide, PmfIsTheFlooredShareOfUseful) {
  // Four bins, useful 0, 1, 3, 6 (total 10), floor 0.2: p = 0.8 u / 10 + 0.05.
  const EmissionGuide g = EmissionGuide::fromUseful(1, 2, {0, 1, 3, 6}, 0.2);
  ASSERT_FALSE(g.uniform());
  const double expected[4] = {0.05, 0.13, 0.29, 0.53};
  double sum = 0.0;
  for (int b = 0; b < 4; ++b) {
    EXPECT_NEAR(g.pmf(b), expected[b], 1e-15) << b;
    sum += g.pmf(b);
  }
  EXPECT_NEAR(sum, 1.0, 1e-15);
  // Nothing useful, or a floor of 1: the uniform guide.
  EXPECT_TRUE(EmissionGuide::fromUseful(1, 2, {0, 0, 0, 0}, 0.2).uniform());
  EXPECT_TRUE(EmissionGuide::fromUseful(1, 2, {0, 1, 3, 6}, 1.0).uniform());
}

TEST(EmissionGuide, CoarsenAndAggregate) {
  int slices = 8, dirRes = 16;
  // 8 x 256 bins need 16,384 useful photons at 8 per bin: 10,000 supports 8 x 8 x 8 = 512 bins.
  ASSERT_TRUE(EmissionGuide::coarsen(10000, 8, slices, dirRes));
  EXPECT_EQ(slices, 8);
  EXPECT_EQ(dirRes, 8);
  // 100 useful: 12 bins at most -> 8 x 1 x 1 (the direction grid halves first).
  slices = 8, dirRes = 16;
  ASSERT_TRUE(EmissionGuide::coarsen(100, 8, slices, dirRes));
  EXPECT_EQ(slices, 8);
  EXPECT_EQ(dirRes, 1);
  slices = 8, dirRes = 16;
  EXPECT_FALSE(EmissionGuide::coarsen(7, 8, slices, dirRes));

  // Two slices of 4 x 4 into one slice of 2 x 2: each coarse bin sums its 8 fine ones.
  std::vector<double> fine(32);
  for (int b = 0; b < 32; ++b) fine[size_t(b)] = double(b);
  const std::vector<double> coarse = EmissionGuide::aggregate(fine, 2, 4, 1, 2);
  ASSERT_EQ(coarse.size(), 4u);
  // Coarse bin (row 0, column 0) holds fine rows 0-1, columns 0-1 of both slices.
  EXPECT_EQ(coarse[0], (0 + 1 + 4 + 5) + (16 + 17 + 20 + 21));
  EXPECT_EQ(coarse[3], (10 + 11 + 14 + 15) + (26 + 27 + 30 + 31));
  EXPECT_EQ(coarse[0] + coarse[1] + coarse[2] + coarse[3], 31.0 * 32.0 / 2.0);
}

TEST(EmissionGuide, GuidedSamplesHaveTheGuidesDensityAndUnbiasedWeights) {
  // Two slices of 4 x 4 bins with uneven useful counts. Drawn 400,000 times: each bin's share
  // within 5 sigma of its pmf, every remapped sample inside the bin its weight belongs to, and
  // the weighted mean of f(u) = 3 uLight^2 * 2 x * (1 + cos(2 pi y)) equal to its integral over
  // the unit cube, 1, within 5 estimated standard errors.
  std::vector<double> useful(32, 0.0);
  useful[3] = 50;
  useful[9] = 10;
  useful[17] = 200;
  useful[30] = 1;
  const EmissionGuide g = EmissionGuide::fromUseful(2, 4, useful, 0.25);
  Rng rng(42, 0);
  const int n = 400000;
  std::vector<int> hits(32, 0);
  double sum = 0.0, sum2 = 0.0;
  for (int k = 0; k < n; ++k) {
    double uLight = double(rng.nextU32()) * 0x1p-32;
    Vec2 uDir = rng.uniform2();
    const double w = g.remap(uLight, uDir);
    ASSERT_GE(uLight, 0.0);
    ASSERT_LT(uLight, 1.0);
    ASSERT_TRUE(uDir.x >= 0.0f && uDir.x < 1.0f && uDir.y >= 0.0f && uDir.y < 1.0f);
    const int b = g.binOf(uLight, uDir);
    ASSERT_NEAR(w, 1.0 / (32.0 * g.pmf(b)), 1e-12);
    ++hits[size_t(b)];
    const double f = 3.0 * uLight * uLight * 2.0 * double(uDir.x) * (1.0 + std::cos(2.0 * kPi * double(uDir.y)));
    sum += w * f;
    sum2 += (w * f) * (w * f);
  }
  for (int b = 0; b < 32; ++b) {
    const double p = g.pmf(b);
    EXPECT_NEAR(hits[size_t(b)], n * p, 5.0 * std::sqrt(n * p * (1.0 - p))) << b;
  }
  const double mean = sum / n;
  const double se = std::sqrt((sum2 / n - mean * mean) / n);
  EXPECT_NEAR(mean, 1.0, 5.0 * se);
}

TEST(EmissionGuide, ExpectedYieldByHand) {
  // Two bins, 100 pilot photons (50 per bin), useful 20 and 0.
  const std::vector<double> useful = {20, 0};
  double per = 0.0, effective = 0.0;
  // Uniform: 0.2 useful per photon, all of weight 1.
  EmissionGuide(1, 1).expectedYield({20}, 100, per, effective);
  EXPECT_DOUBLE_EQ(per, 0.2);
  EXPECT_DOUBLE_EQ(effective, 0.2);
  // Floor 0.5: p = (0.75, 0.25); bin 0's rate 0.4, so 0.3 useful per photon, each of weight
  // 1 / (2 * 0.75) = 2/3: effective (0.2)^2 / (0.3 * 4/9) = 0.3 (equal weights lose nothing).
  const EmissionGuide g = EmissionGuide::fromUseful(2, 1, {20, 0}, 0.5);
  ASSERT_EQ(g.bins(), 2);
  g.expectedYield({20, 0}, 100, per, effective);
  EXPECT_NEAR(per, 0.3, 1e-12);
  EXPECT_NEAR(effective, 0.3, 1e-12);
  // Unequal weights lose: useful (20, 5) with the guide of (20, 0): rates 0.4 and 0.1,
  // per = 0.75 * 0.4 + 0.25 * 0.1 = 0.325; weights 2/3 and 2; sum w = 0.25,
  // sum w^2 = 0.75 * 0.4 * 4/9 + 0.25 * 0.1 * 4 = 0.2333...; effective 0.0625 / 0.2333 = 0.2679.
  g.expectedYield({20, 5}, 100, per, effective);
  EXPECT_NEAR(per, 0.325, 1e-12);
  EXPECT_NEAR(effective, 0.0625 / (0.3 * 4.0 / 9.0 + 0.1), 1e-12);
}

/// A point light of intensity 2 at height 1 above an absorbing plane (the plane of
/// PhotonTracer.PointLightIrradianceOnPlane).
Scene pointOverPlane() {
  const std::string json = R"({
    "camera": {"position": [0, 0.5, -10], "target": [0, 0.5, 0], "up": [0, 1, 0]},
    "materials": {"floor": {"type": "lambertian", "albedo": 0}},
    "shapes": [{"type": "quad", "material": "floor",
                "vertices": [[-100, 0, -100], [-100, 0, 100], [100, 0, 100], [100, 0, -100]]}],
    "lights": [{"type": "point", "position": [0, 1, 0], "intensity": 2}]
  })";
  return parseScene(json, "guide-test", ".");
}

TEST(EmissionGuide, GuidedPhotonsCarryTheClosedFormFlux) {
  // A pilot of 20,000 photons names where those landing on a 0.4 x 0.4 patch under the light
  // left; 200,000 guided photons then put many times more photons on it, and the flux on it and
  // on a patch off to the side (which the guide does not favour) is I Omega, the closed form,
  // within 5 standard deviations estimated from the photons (each emitted photon stores at most
  // one: the plane absorbs).
  const Scene scene = pointOverPlane();
  const Hbvh accel(scene);
  PhotonSettings pilot = test::photonSettings(20000, 0);
  pilot.guide = std::make_shared<EmissionGuide>(1, 16);
  pilot.recordBins = true;
  const PhotonMaps p = tracePhotons(scene, accel, pilot);
  ASSERT_EQ(p.globalBins.size(), p.global.size());
  struct Patch {
    double x0, x1, z0, z1;
    bool in(const Vec3& q) const { return q.x >= x0 && q.x < x1 && q.z >= z0 && q.z < z1; }
  };
  const Patch under{-0.2, 0.2, -0.2, 0.2}, side{0.8, 1.2, -0.2, 0.2};
  std::vector<double> useful(256, 0.0);
  for (size_t i = 0; i < p.global.size(); ++i)
    if (under.in(p.global[i].position)) useful[p.globalBins[i]] += 1.0;

  PhotonSettings guided = pilot;
  guided.photons = 200000;
  guided.guide = std::make_shared<EmissionGuide>(EmissionGuide::fromUseful(1, 16, useful, 0.25));
  guided.recordBins = false;
  PhotonSettings plain = guided;
  plain.guide.reset();
  const PhotonMaps g = tracePhotons(scene, accel, guided), u = tracePhotons(scene, accel, plain);
  EXPECT_TRUE(g.globalBins.empty());
  const double n = double(guided.photons);
  for (int which = 0; which < 2; ++which) {
    const Patch& pa = which == 0 ? under : side;
    double power = 0.0, power2 = 0.0;
    uint64_t countGuided = 0, countPlain = 0;
    for (const Photon& ph : g.global)
      if (pa.in(ph.position)) {
        power += ph.power.x;
        power2 += double(ph.power.x) * ph.power.x;
        ++countGuided;
      }
    for (const Photon& ph : u.global) countPlain += pa.in(ph.position) ? 1 : 0;
    const double expected = 2.0 * rectangleSolidAngle(pa.x0, pa.x1, pa.z0, pa.z1, 1.0);
    // The sum over n emitted photons of X (the power stored on the patch, 0 for most).
    const double sigma = std::sqrt(std::max(0.0, power2 - power * power / n));
    EXPECT_NEAR(power, expected, 5.0 * sigma) << pa.x0;
    if (which == 0) {
      // The favoured patch is sharp: 5 sigma under 5%, from many times the unguided photons.
      EXPECT_LT(5.0 * sigma, 0.05 * expected);
      EXPECT_GT(countGuided, 3 * countPlain);
    }
  }
  // The whole plane's flux is unchanged too (the floor keeps every direction emitted).
  double total = 0.0, total2 = 0.0;
  for (const Photon& ph : g.global) {
    total += ph.power.x;
    total2 += double(ph.power.x) * ph.power.x;
  }
  const double plane = 2.0 * rectangleSolidAngle(-100.0, 100.0, -100.0, 100.0, 1.0);
  EXPECT_NEAR(total, plane, 5.0 * std::sqrt(total2 - total * total / n));
}

}  // namespace
}  // namespace voxcone

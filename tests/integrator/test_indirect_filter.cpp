// The screen-space indirect filter against hand-computed cases: it averages one surface only.

#include "voxcone/core/rng.h"
#include "voxcone/integrator/indirect_filter.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace voxcone {
namespace {

/// A w x h view of the plane z = 0 (normal +z, material 0, footprint 1 per pixel) whose
/// pixels hold `value`.
IndirectBuffer planeBuffer(int w, int h, const Vec3& value) {
  IndirectBuffer b;
  b.width = w;
  b.height = h;
  const size_t n = size_t(w) * size_t(h);
  b.indirect.assign(n, value);
  b.normal.assign(n, Vec3(0, 0, 1));
  b.material.assign(n, 0u);
  b.footprint.assign(n, 1.0f);
  b.filterable.assign(n, 1u);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) b.position.push_back(Vec3(float(x), float(y), 0.0f));
  return b;
}

TEST(IndirectFilter, ConstantLightStaysAndRadiusZeroIsTheIdentity) {
  IndirectBuffer b = planeBuffer(9, 7, Vec3(0.25f, 0.5f, 1.0f));
  b.indirect[20] = Vec3(3.0f);
  EXPECT_EQ(filterIndirect(b, 0), b.indirect);
  b.indirect[20] = Vec3(0.25f, 0.5f, 1.0f);
  for (const Vec3& v : filterIndirect(b, 3)) {
    EXPECT_NEAR(v.x, 0.25f, 1e-6f);
    EXPECT_NEAR(v.z, 1.0f, 1e-6f);
  }
}

TEST(IndirectFilter, HandComputedWeightsOnARow) {
  // Three pixels in a row on one plane, radius 2 (sigma 1): the middle one takes
  // (e^-0.5 * 1 + 1 * 4 + e^-0.5 * 7) / (1 + 2 e^-0.5).
  IndirectBuffer b = planeBuffer(3, 1, Vec3(0.0f));
  b.indirect = {Vec3(1.0f), Vec3(4.0f), Vec3(7.0f)};
  const float g = std::exp(-0.5f);
  const std::vector<Vec3> out = filterIndirect(b, 2);
  EXPECT_NEAR(out[1].x, (g * 1.0f + 4.0f + g * 7.0f) / (1.0f + 2.0f * g), 1e-5f);
  // The first: itself, its neighbour at 1 (e^-0.5) and the one at 2 (e^-2).
  EXPECT_NEAR(out[0].x, (1.0f + g * 4.0f + std::exp(-2.0f) * 7.0f) / (1.0f + g + std::exp(-2.0f)), 1e-5f);
}

TEST(IndirectFilter, NeverMixesMaterialsCornersPlanesOrUnfilterablePixels) {
  // Left half material 0 with light 1, right half material 1 with light 5: each side keeps
  // its own value exactly.
  IndirectBuffer b = planeBuffer(8, 4, Vec3(1.0f));
  for (int y = 0; y < 4; ++y)
    for (int x = 4; x < 8; ++x) {
      b.material[size_t(y) * 8 + x] = 1u;
      b.indirect[size_t(y) * 8 + x] = Vec3(5.0f);
    }
  std::vector<Vec3> out = filterIndirect(b, 3);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 8; ++x) EXPECT_EQ(out[size_t(y) * 8 + x].x, x < 4 ? 1.0f : 5.0f) << x << "," << y;
  // A corner: the right half's normal turned by 90 degrees (same material).
  b = planeBuffer(8, 4, Vec3(1.0f));
  for (int y = 0; y < 4; ++y)
    for (int x = 4; x < 8; ++x) {
      b.normal[size_t(y) * 8 + x] = Vec3(1, 0, 0);
      b.indirect[size_t(y) * 8 + x] = Vec3(5.0f);
    }
  out = filterIndirect(b, 3);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 8; ++x) EXPECT_EQ(out[size_t(y) * 8 + x].x, x < 4 ? 1.0f : 5.0f) << x << "," << y;
  // A parallel surface 3 footprints behind (a step): kept apart.
  b = planeBuffer(8, 4, Vec3(1.0f));
  for (int y = 0; y < 4; ++y)
    for (int x = 4; x < 8; ++x) {
      b.position[size_t(y) * 8 + x].z = -3.0f;
      b.indirect[size_t(y) * 8 + x] = Vec3(5.0f);
    }
  out = filterIndirect(b, 3);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 8; ++x) EXPECT_EQ(out[size_t(y) * 8 + x].x, x < 4 ? 1.0f : 5.0f) << x << "," << y;
  // An unfilterable pixel (an edge inside it) keeps its value and lends it to nobody.
  b = planeBuffer(5, 5, Vec3(1.0f));
  b.indirect[12] = Vec3(9.0f);
  b.filterable[12] = 0u;
  out = filterIndirect(b, 2);
  EXPECT_EQ(out[12].x, 9.0f);
  for (size_t p = 0; p < out.size(); ++p)
    if (p != 12) {
      EXPECT_NEAR(out[p].x, 1.0f, 1e-6f) << p;
    }
}

TEST(IndirectFilter, LightDoesNotCrossACutLink) {
  // One floor seen on both sides of a wall thinner than a pixel (the thin-wall scene): the
  // links between columns 3 and 4 are cut down the whole image, so neither side borrows the
  // other's light although every other test passes.
  IndirectBuffer b = planeBuffer(8, 6, Vec3(1.0f));
  b.link.assign(b.indirect.size(), 3u);
  for (int y = 0; y < 6; ++y) {
    b.link[size_t(y) * 8 + 3] &= ~uint8_t(1u);
    for (int x = 4; x < 8; ++x) b.indirect[size_t(y) * 8 + x] = Vec3(0.0f);
  }
  std::vector<Vec3> out = filterIndirect(b, 3);
  for (int y = 0; y < 6; ++y)
    for (int x = 0; x < 8; ++x) EXPECT_EQ(out[size_t(y) * 8 + x].x, x < 4 ? 1.0f : 0.0f) << x << "," << y;
  // A gap in the cut at row 0: pixels whose window holds the gap reach through it; (7, 5),
  // whose window is rows 2-5, cannot.
  b.link[3] |= 1u;
  out = filterIndirect(b, 3);
  EXPECT_GT(out[4].x, 0.0f);
  EXPECT_EQ(out[size_t(5) * 8 + 7].x, 0.0f);
}

TEST(IndirectFilter, PixelsWithoutEstimatesTakeTheirNeighboursOnly) {
  // A row of five on one plane, radius 2 (sigma 1), only pixels 0 and 3 estimated (1 and 7):
  // pixel 1 takes (e^-0.5 * 1 + e^-2 * 7) / (e^-0.5 + e^-2), pixel 4 the 7 of its neighbour
  // alone, pixel 0 (its own 1 and pixel 3 beyond the window) keeps 1. Values of pixels
  // without an estimate are never read.
  IndirectBuffer b = planeBuffer(5, 1, Vec3(0.0f));
  b.indirect = {Vec3(1.0f), Vec3(100.0f), Vec3(100.0f), Vec3(7.0f), Vec3(100.0f)};
  b.estimated = {1, 0, 0, 1, 0};
  const float g1 = std::exp(-0.5f), g2 = std::exp(-2.0f);
  const std::vector<Vec3> out = filterIndirect(b, 2);
  EXPECT_NEAR(out[1].x, (g1 * 1.0f + g2 * 7.0f) / (g1 + g2), 1e-5f);
  EXPECT_NEAR(out[2].x, (g2 * 1.0f + g1 * 7.0f) / (g1 + g2), 1e-5f);
  EXPECT_NEAR(out[4].x, 7.0f, 1e-6f);
  EXPECT_NEAR(out[0].x, 1.0f, 1e-6f);
  EXPECT_EQ(unfilledPixels(b, 2), std::vector<uint8_t>(5, 0u));
  // A cut link between 2 and 3: pixel 4 still has 3, pixel 2 only 0 (at 2); radius 1: pixel 2
  // reaches nothing estimated and is unfilled, as is none other.
  b.link.assign(5, 1u);
  b.link[2] = 0u;
  EXPECT_NEAR(filterIndirect(b, 2)[2].x, 1.0f, 1e-6f);
  EXPECT_EQ(unfilledPixels(b, 1), (std::vector<uint8_t>{0, 0, 1, 0, 0}));
  // An unfilterable pixel is never unfilled (renderImage gathers it anyway).
  b.filterable[2] = 0u;
  EXPECT_EQ(unfilledPixels(b, 1), std::vector<uint8_t>(5, 0u));
}

TEST(IndirectFilter, ColumnsCarryTheRowsSums) {
  // 1 x 3 column, the middle one estimated only: the top and bottom take its value; a 3 x 3
  // plane with only the centre estimated: every pixel takes it (rows, then columns).
  IndirectBuffer b = planeBuffer(3, 3, Vec3(0.0f));
  b.indirect[4] = Vec3(2.5f);
  b.estimated.assign(9, 0u);
  b.estimated[4] = 1u;
  for (const Vec3& v : filterIndirect(b, 2)) EXPECT_NEAR(v.x, 2.5f, 1e-6f);
  EXPECT_EQ(unfilledPixels(b, 1), std::vector<uint8_t>(9, 0u));
}

TEST(IndirectFilter, NoiseOnOneSurfaceFallsByTheKernelsSampleCount) {
  // Independent noise of variance s^2 on one plane: radius 3 (sigma 1.5) keeps the mean and
  // divides the variance by sum(w)^2 / sum(w^2) = 4 pi sigma^2 = 28 in the interior (measured
  // here over the interior pixels; at least 20x).
  constexpr int kW = 64, kH = 64;
  IndirectBuffer b = planeBuffer(kW, kH, Vec3(0.0f));
  Rng rng(3, 3);
  for (Vec3& v : b.indirect) v = Vec3(1.0f + (rng.uniform() - 0.5f));
  const std::vector<Vec3> out = filterIndirect(b, 3);
  const auto stats = [&](const std::vector<Vec3>& img, double& mean, double& var) {
    double s = 0.0, s2 = 0.0;
    int n = 0;
    for (int y = 3; y < kH - 3; ++y)
      for (int x = 3; x < kW - 3; ++x) {
        const double v = img[size_t(y) * kW + x].x;
        s += v;
        s2 += v * v;
        ++n;
      }
    mean = s / n;
    var = s2 / n - mean * mean;
  };
  double m0, v0, m1, v1;
  stats(b.indirect, m0, v0);
  stats(out, m1, v1);
  EXPECT_NEAR(m1, m0, 0.01);
  EXPECT_GT(v0 / v1, 20.0);
}

TEST(IndirectFilter, ReachIsTheDistanceToTheSurfaceThatMeetsThePixels) {
  // A floor (z = 0, normal +z) for x < 12 and a wall for x >= 12 standing on it (x = 12, z = x -
  // 11.5, normal -x): a floor pixel x reaches scale * its distance to the wall's first pixel in
  // its row, sqrt((12 - x)^2 + 0.25), when that pixel is within the radius; farther, infinitely.
  constexpr int kW = 24, kH = 8, kRadius = 6;
  const auto corner = [&] {
    IndirectBuffer b = planeBuffer(kW, kH, Vec3(1.0f));
    for (int y = 0; y < kH; ++y)
      for (int x = 12; x < kW; ++x) {
        b.position[size_t(y) * kW + x] = Vec3(12.0f, float(y), float(x) - 11.5f);
        b.normal[size_t(y) * kW + x] = Vec3(-1, 0, 0);
      }
    return b;
  };
  IndirectBuffer b = corner();
  std::vector<float> reach = surfaceReach(b, kRadius, 2.0f);
  for (int x = 0; x < 12; ++x) {
    const float expected = 12 - x <= kRadius ? 2.0f * std::sqrt(float((12 - x) * (12 - x)) + 0.25f)
                                             : std::numeric_limits<float>::infinity();
    EXPECT_FLOAT_EQ(reach[size_t(3) * kW + x], expected) << x;
  }
  // The edge's own pixels (seeing both) are passed over: the wall is still found beyond them.
  for (int y = 0; y < kH; ++y) b.filterable[size_t(y) * kW + 12] = b.filterable[size_t(y) * kW + 13] = 0u;
  reach = surfaceReach(b, kRadius, 1.0f);
  EXPECT_FLOAT_EQ(reach[size_t(3) * kW + 10], std::sqrt(4.0f + 2.5f * 2.5f));  // to (12, 3, 2.5)
  // Three such pixels in a row: what lies beyond is not taken as meeting the floor.
  for (int y = 0; y < kH; ++y) b.filterable[size_t(y) * kW + 14] = 0u;
  reach = surfaceReach(b, kRadius, 1.0f);
  EXPECT_TRUE(std::isinf(reach[size_t(3) * kW + 10]));
  // One plane, or nothing beside it (the sky): no limit.
  b = planeBuffer(kW, kH, Vec3(1.0f));
  for (float r : surfaceReach(b, kRadius, 1.0f)) EXPECT_TRUE(std::isinf(r));
  for (int y = 0; y < kH; ++y)
    for (int x = 12; x < kW; ++x) b.filterable[size_t(y) * kW + x] = 0u;
  for (float r : surfaceReach(b, kRadius, 1.0f)) EXPECT_TRUE(std::isinf(r));
  // A floor 50 units behind the pixel's (a silhouette, not an edge): reach 50 and more.
  b = planeBuffer(kW, kH, Vec3(1.0f));
  for (int y = 0; y < kH; ++y)
    for (int x = 12; x < kW; ++x) b.position[size_t(y) * kW + x].z = -50.0f;
  reach = surfaceReach(b, kRadius, 1.0f);
  EXPECT_GE(reach[size_t(3) * kW + 11], 50.0f);
}

TEST(IndirectFilter, ReachLimitsWhatAPixelTakesAndGives) {
  // A row, radius 4 (sigma 2, weight e^(-d^2 / 8) at distance d), every pixel reaching 1: the
  // middle one takes its two neighbours only; a neighbour reaching 0.5 is left out both ways
  // (the walk also stops there: the pixel beyond it is not reached).
  IndirectBuffer b = planeBuffer(9, 1, Vec3(0.0f));
  for (int x = 0; x < 9; ++x) b.indirect[size_t(x)] = Vec3(float(x * x));
  b.reach.assign(9, 1.0f);
  const float g = std::exp(-1.0f / 8.0f);
  std::vector<Vec3> out = filterIndirect(b, 4);
  EXPECT_NEAR(out[4].x, (g * 9.0f + 16.0f + g * 25.0f) / (1.0f + 2.0f * g), 1e-4f);
  b.reach[5] = 0.5f;
  out = filterIndirect(b, 4);
  EXPECT_NEAR(out[4].x, (g * 9.0f + 16.0f) / (1.0f + g), 1e-4f);
  EXPECT_EQ(out[5].x, 25.0f);
  // Unlimited, the middle one takes all nine.
  b.reach.clear();
  out = filterIndirect(b, 4);
  double num = 0.0, den = 0.0;
  for (int x = 0; x < 9; ++x) {
    const double w = std::exp(-double((x - 4) * (x - 4)) / 8.0);
    num += w * x * x;
    den += w;
  }
  EXPECT_NEAR(out[4].x, num / den, 1e-4);
}

}  // namespace
}  // namespace voxcone

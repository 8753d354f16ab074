// The light tree against its own definition: at any shading point its choice probabilities
// sum to at most one, sample() reports the probability pmf() recomputes, a stratified set of
// numbers gives every light its share to within one sample, independent numbers pass a
// chi-square test against the probabilities, and no light that can reach the point is ever
// given probability 0 (that would be bias, not noise).
//
// At most one, not one: as in pbrt-v4, a node's bounds are looser than its children's, so the
// walk can reach a node whose two children both bound zero (none of their lights can reach the
// point) and then chooses nothing. That outcome is unbiased (the lights it stands for add
// nothing) and has probability 1 - sum(pmf); the chi-square test counts it as its own cell.

#include "voxcone/core/rng.h"
#include "voxcone/scene/light_tree.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

namespace voxcone {
namespace {

struct TestLight {
  Vec3 v0, v1, v2;  // a triangle; v0 == v1 == v2 for a point light
  bool point = false;
  bool twoSided = false;
};

Vec3 randomUnit(Rng& rng) {
  const float z = 1.0f - 2.0f * rng.uniform();
  const float r = std::sqrt(std::max(0.0f, 1.0f - z * z));
  const float phi = 2.0f * kPi * rng.uniform();
  return Vec3(r * std::cos(phi), r * std::sin(phi), z);
}

/// `n` lights in the box [-5, 5]^3: triangles of 2 to 10 cm in every orientation (one in eight
/// two-sided), one in sixteen a point light, powers spread over four decades.
struct LightSet {
  std::vector<TestLight> lights;
  std::vector<LightBounds> bounds;
};
LightSet randomLights(int n, uint64_t seed) {
  Rng rng(seed, 0);
  LightSet set;
  for (int i = 0; i < n; ++i) {
    TestLight l;
    const Vec3 c = Vec3(rng.uniform(), rng.uniform(), rng.uniform()) * 10.0f - 5.0f;
    const float phi = std::pow(10.0f, 4.0f * rng.uniform() - 2.0f);
    LightBounds lb;
    lb.phi = phi;
    if (rng.uniform() < 1.0f / 16.0f) {
      l.point = true;
      l.v0 = l.v1 = l.v2 = c;
      lb.bounds = Bounds3(c, c);
      lb.cosTheta_o = -1.0f;
    } else {
      const float s = 0.02f + 0.08f * rng.uniform();
      l.v0 = c + s * randomUnit(rng);
      l.v1 = c + s * randomUnit(rng);
      l.v2 = c + s * randomUnit(rng);
      l.twoSided = rng.uniform() < 0.125f;
      lb.bounds = Bounds3(l.v0, l.v1);
      lb.bounds.extend(l.v2);
      lb.w = glm::normalize(glm::cross(l.v1 - l.v0, l.v2 - l.v0));
      lb.twoSided = l.twoSided;
    }
    set.lights.push_back(l);
    set.bounds.push_back(lb);
  }
  return set;
}

/// Can light l send light to p through a surface with normal n (either side)? Checked at the
/// triangle's vertices and centroid: a vertex in front of the emitter and off p's tangent plane.
bool canReach(const TestLight& l, const Vec3& p, const Vec3& n) {
  const Vec3 pts[4] = {l.v0, l.v1, l.v2, (l.v0 + l.v1 + l.v2) / 3.0f};
  const Vec3 ln = l.point ? Vec3(0.0f) : glm::normalize(glm::cross(l.v1 - l.v0, l.v2 - l.v0));
  for (const Vec3& q : pts) {
    const Vec3 d = glm::normalize(p - q);
    const float cosL = glm::dot(ln, d);
    const bool emits = l.point || cosL > 1e-3f || (l.twoSided && cosL < -1e-3f);
    if (emits && std::fabs(glm::dot(n, d)) > 1e-3f) return true;
  }
  return false;
}

/// Shading points: inside the lights' box and around it, normals in every direction.
std::vector<std::pair<Vec3, Vec3>> shadingPoints(int n, uint64_t seed) {
  Rng rng(seed, 0);
  std::vector<std::pair<Vec3, Vec3>> pts;
  for (int i = 0; i < n; ++i) {
    const Vec3 p = Vec3(rng.uniform(), rng.uniform(), rng.uniform()) * 16.0f - 8.0f;
    pts.emplace_back(p, randomUnit(rng));
  }
  return pts;
}

TEST(LightTree, ProbabilitiesSumToAtMostOneAndSampleReportsWhatPmfRecomputes) {
  // With 256 lights in every orientation (the worst case for the nodes' cones of normals), the
  // mean probability of choosing nothing over the shading points is below 5% (measured 2.9%).
  double deficit256 = 0.0;
  int points256 = 0;
  for (int n : {1, 2, 3, 16, 255, 256}) {
    const LightSet set = randomLights(n, 7 + uint64_t(n));
    const LightTree tree(set.bounds);
    ASSERT_EQ(tree.nodeCount(), size_t(2 * n - 1));
    for (const auto& [p, nrm] : shadingPoints(64, 11)) {
      for (const Vec3* normal : {&nrm, static_cast<const Vec3*>(nullptr)}) {
        double sum = 0.0;
        bool reachable = false;
        for (int l = 0; l < n; ++l) {
          sum += tree.pmf(p, normal, uint32_t(l));
          reachable = reachable || set.bounds[size_t(l)].importance(p, normal) > 0.0f;
        }
        EXPECT_LE(sum, 1.0 + 1e-5) << n << " lights";
        if (!reachable && n > 1) {
          EXPECT_EQ(sum, 0.0);  // one light is its own root: always chosen
        }
        if (n == 256) {
          ++points256;
          deficit256 += 1.0 - sum;
        }
        for (float u0 : {0.0f, 0.1f, 0.37f, 0.5f, 0.93f, kOneMinusEpsilon}) {
          float u = u0, pmf = 0.0f;
          uint32_t light = 0;
          if (!tree.sample(p, normal, u, light, pmf)) continue;
          ASSERT_LT(light, uint32_t(n));
          EXPECT_NEAR(pmf, tree.pmf(p, normal, light), 1e-6f * tree.pmf(p, normal, light));
          EXPECT_GE(u, 0.0f);
          EXPECT_LT(u, 1.0f);
        }
      }
    }
  }
  std::printf("256 lights: mean probability of choosing nothing %.2e\n", deficit256 / points256);
  EXPECT_LT(deficit256 / points256, 0.05);
}

TEST(LightTree, NoLightThatCanReachThePointHasProbabilityZero) {
  const LightSet set = randomLights(256, 3);
  const LightTree tree(set.bounds);
  int reachable = 0;
  for (const auto& [p, nrm] : shadingPoints(200, 5))
    for (size_t l = 0; l < set.lights.size(); ++l)
      if (canReach(set.lights[l], p, nrm)) {
        ++reachable;
        EXPECT_GT(tree.pmf(p, &nrm, uint32_t(l)), 0.0f) << "light " << l << " at (" << p.x << ", " << p.y << ", " << p.z
                                                        << ")";
      }
  EXPECT_GT(reachable, 200 * 256 / 4);
}

TEST(LightTree, StratifiedNumbersGiveEveryLightItsShareWithinOneSample) {
  // The walk down rescales u at each node, so the numbers choosing a light form one interval
  // of length pmf: M evenly spaced numbers choose it pmf * M times, give or take one.
  const LightSet set = randomLights(256, 21);
  const LightTree tree(set.bounds);
  constexpr int kM = 1 << 14;
  for (const auto& [p, nrm] : shadingPoints(16, 23)) {
    std::vector<int> count(set.lights.size(), 0);
    for (int i = 0; i < kM; ++i) {
      float u = (float(i) + 0.5f) / float(kM), pmf = 0.0f;
      uint32_t light = 0;
      if (tree.sample(p, &nrm, u, light, pmf)) ++count[light];
    }
    for (size_t l = 0; l < count.size(); ++l)
      EXPECT_LE(std::fabs(count[l] - double(tree.pmf(p, &nrm, uint32_t(l))) * kM), 1.01) << "light " << l;
  }
}

TEST(LightTree, IndependentSamplesPassAChiSquareTestAgainstThePmf) {
  // 200,000 independent choices at each of 8 points; lights (and "nothing") expected fewer
  // than 5 times are pooled into one cell. Wilson-Hilferty turns X^2 with k degrees of freedom into a normal
  // deviate; a wrong probability anywhere (say one branch's p0 swapped) gives z in the hundreds.
  const LightSet set = randomLights(256, 31);
  const LightTree tree(set.bounds);
  constexpr int kN = 200000;
  Rng rng(99, 0);
  for (const auto& [p, nrm] : shadingPoints(8, 37)) {
    std::vector<int> count(set.lights.size(), 0);
    int nothing = 0;
    for (int i = 0; i < kN; ++i) {
      float u = rng.uniform(), pmf = 0.0f;
      uint32_t light = 0;
      if (tree.sample(p, &nrm, u, light, pmf)) ++count[light];
      else ++nothing;
    }
    double chi2 = 0.0, pooledExpected = 0.0, pooledObserved = 0.0, sum = 0.0;
    int cells = 0;
    for (size_t l = 0; l < count.size(); ++l) sum += tree.pmf(p, &nrm, uint32_t(l));
    // The outcome "nothing", a cell like any light's.
    const double nothingExpected = std::max(0.0, 1.0 - sum) * kN;
    if (nothingExpected >= 5.0) {
      chi2 += sqr(nothing - nothingExpected) / nothingExpected;
      ++cells;
    } else {
      pooledExpected += nothingExpected;
      pooledObserved += nothing;
    }
    for (size_t l = 0; l < count.size(); ++l) {
      const double expected = double(tree.pmf(p, &nrm, uint32_t(l))) * kN;
      if (expected < 5.0) {
        pooledExpected += expected;
        pooledObserved += count[l];
        continue;
      }
      chi2 += sqr(count[l] - expected) / expected;
      ++cells;
    }
    if (pooledExpected >= 5.0) {
      chi2 += sqr(pooledObserved - pooledExpected) / pooledExpected;
      ++cells;
    } else {
      EXPECT_LE(pooledObserved, 20.0);
    }
    const double k = cells - 1;
    ASSERT_GT(k, 10);
    const double z = (std::cbrt(chi2 / k) - (1.0 - 2.0 / (9.0 * k))) / std::sqrt(2.0 / (9.0 * k));
    EXPECT_LT(z, 4.0) << "chi2 " << chi2 << " with " << k << " degrees of freedom";
  }
}

TEST(LightTree, SplitChoicesReportTheirGroupsPmfAndGiveEveryLightItsShare) {
  // With splitting each choice's probability is its own group's, which pmfSplit recomputes;
  // each light lies in exactly one group, whose walk down keeps a stratified set of numbers
  // stratified: over M evenly spaced numbers every light is chosen pmfSplit * M times, give or
  // take one (so sum over choices of g(light) / pmf estimates sum over lights of g, whatever g).
  // Splitting at 0.2, 0.8 and pi/2 rad (there only nodes whose sphere holds the point split).
  const LightSet set = randomLights(256, 41);
  const LightTree tree(set.bounds);
  constexpr int kM = 4096;
  for (const float angle : {0.2f, 0.8f, 1.5708f}) {
    int most = 0;
    for (const auto& [p, nrm] : shadingPoints(24, 43)) {
      std::vector<int> count(set.lights.size(), 0);
      for (int i = 0; i < kM; ++i) {
        LightTree::Choice c[LightTree::kMaxChoices];
        const int n = tree.sampleSplit(p, &nrm, (float(i) + 0.5f) / float(kM), angle, c);
        ASSERT_LE(n, LightTree::kMaxChoices);
        most = std::max(most, n);
        for (int k = 0; k < n; ++k) {
          ASSERT_GT(c[k].pmf, 0.0f);
          EXPECT_NEAR(c[k].pmf, tree.pmfSplit(p, &nrm, c[k].light, angle), 1e-5f * c[k].pmf);
          EXPECT_GE(c[k].u, 0.0f);
          EXPECT_LT(c[k].u, 1.0f);
          ++count[c[k].light];
        }
      }
      for (size_t l = 0; l < count.size(); ++l) {
        const double expected = double(tree.pmfSplit(p, &nrm, uint32_t(l), angle)) * kM;
        EXPECT_LE(std::fabs(count[l] - expected), 1.01) << "light " << l << " angle " << angle;
        if (set.bounds[l].importance(p, &nrm) > 0.0f) {
          EXPECT_GT(expected, 0.0) << "light " << l;
        }
      }
    }
    std::printf("split angle %.2f rad: at most %d choices\n", angle, most);
    EXPECT_GT(most, 1);  // every point lies inside the root's sphere at least
  }
}

}  // namespace
}  // namespace voxcone

// LightProximity: the nearest point of a triangle against dense sampling, the distance to the
// nearest light against brute force (emissive triangles and point lights, a grid grown for a
// light far larger than the radius), and the cone share's law.

#include "voxcone/photon/light_proximity.h"

#include "voxcone/core/rng.h"
#include "voxcone/scene/scene.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>

namespace voxcone {
namespace {

/// Two emissive quads (one 0.5 x 0.5 under a ceiling at y = 2, one a 100 m square at y = -1 when
/// `huge`), a point light, and a non-emissive floor that must not count.
Scene lightsScene(bool huge) {
  std::string shapes = R"(
      {"type": "quad", "material": "floor", "vertices": [[-3, 0, -3], [-3, 0, 3], [3, 0, 3], [3, 0, -3]]},
      {"type": "quad", "material": "lamp", "vertices": [[0.25, 1.98, 0.25], [0.75, 1.98, 0.25], [0.75, 1.98, 0.75], [0.25, 1.98, 0.75]]})";
  if (huge)
    shapes += R"(,
      {"type": "quad", "material": "lamp", "vertices": [[-50, -1, -50], [50, -1, -50], [50, -1, 50], [-50, -1, 50]]})";
  const std::string json = R"({
    "camera": {"position": [0, 1, -5], "target": [0, 1, 0], "up": [0, 1, 0]},
    "materials": {"floor": {"type": "lambertian", "albedo": 0.5},
                  "lamp": {"type": "lambertian", "albedo": 0.5, "emission": [1, 1, 1]}},
    "shapes": [)" + shapes + R"(],
    "lights": [{"type": "point", "position": [-1, 1, 0.5], "intensity": [1, 1, 1]}]
  })";
  return parseScene(json, "proximity", ".");
}

/// Distance from p to the nearest of `scene`'s emissive triangles and point lights, by brute force.
float bruteDistance(const Scene& scene, const Vec3& p) {
  float best = kInf;
  for (size_t t = 0; t < scene.triangles.size(); ++t) {
    if (!scene.materials[scene.triMaterial[t]].isEmissive()) continue;
    const UVec3& tri = scene.triangles[t];
    const Vec3 c = LightProximity::closestOnTriangle(p, scene.positions[tri.x], scene.positions[tri.y], scene.positions[tri.z]);
    best = std::min(best, glm::length(p - c));
  }
  for (const PointLight& l : scene.pointLights) best = std::min(best, glm::length(p - l.position));
  return best;
}

TEST(LightProximity, TheClosestPointOfATriangleIsNoFartherThanAnyOfItsPoints) {
  Rng rng(7, 0);
  const auto point = [&](float s) { return Vec3(rng.uniform(), rng.uniform(), rng.uniform()) * (2.0f * s) - Vec3(s); };
  for (int trial = 0; trial < 200; ++trial) {
    const Vec3 a = point(1.0f), b = point(1.0f), c = point(1.0f), p = point(2.0f);
    const Vec3 q = LightProximity::closestOnTriangle(p, a, b, c);
    // q lies on the triangle: its barycentrics are in [0, 1] and sum to 1.
    const Vec3 n = glm::cross(b - a, c - a);
    const float area2 = glm::dot(n, n);
    const float u = glm::dot(glm::cross(c - b, q - b), n) / area2, v = glm::dot(glm::cross(a - c, q - c), n) / area2;
    EXPECT_GE(u, -1e-4f);
    EXPECT_GE(v, -1e-4f);
    EXPECT_LE(u + v, 1.0f + 1e-4f);
    EXPECT_NEAR(glm::dot(q - a, n), 0.0f, 1e-4f * std::sqrt(area2));
    // No point of a dense barycentric grid (and no vertex) is nearer to p.
    const float dq = glm::length(p - q);
    constexpr int kSteps = 60;
    for (int i = 0; i <= kSteps; ++i)
      for (int j = 0; i + j <= kSteps; ++j) {
        const Vec3 s = a + (b - a) * (float(i) / kSteps) + (c - a) * (float(j) / kSteps);
        ASSERT_LE(dq, glm::length(p - s) + 1e-5f) << "trial " << trial;
      }
  }
}

TEST(LightProximity, DistanceIsTheNearestLightsWithinTheRadiusAndInfinityBeyond) {
  for (const bool huge : {false, true}) {
    const Scene scene = lightsScene(huge);
    // 0.05 against a 100 m lamp: 4 million cells and more, so the cells grow; the distances
    // must not change for it.
    const float radius = huge ? 0.05f : 0.4f;
    const LightProximity near(scene, radius);
    ASSERT_FALSE(near.empty());
    Rng rng(11, huge ? 1 : 0);
    int within = 0;
    for (int i = 0; i < 20000; ++i) {
      const Vec3 p(rng.uniform() * 4.0f - 2.0f, rng.uniform() * 3.2f - 1.1f, rng.uniform() * 4.0f - 2.0f);
      const float brute = bruteDistance(scene, p), d = near.distance(p);
      if (brute < radius) {
        ++within;
        ASSERT_NEAR(d, brute, 1e-5f) << "at " << p.x << " " << p.y << " " << p.z;
      } else {
        ASSERT_EQ(d, kInf) << "at " << p.x << " " << p.y << " " << p.z;
      }
    }
    EXPECT_GT(within, 100) << "the test points must reach inside the radius";
  }
}

TEST(LightProximity, TheConeShareFallsAsTheSquareOfTheDistanceWithinTheRadius) {
  const Scene scene = lightsScene(false);
  const LightProximity near(scene, 0.4f);
  const Vec3 onLamp(0.5f, 1.98f, 0.5f);
  EXPECT_EQ(near.coneShare(onLamp), 0.0f);
  EXPECT_NEAR(near.coneShare(onLamp + Vec3(0.0f, -0.2f, 0.0f)), 0.25f, 1e-5f);   // d = r / 2
  EXPECT_NEAR(near.coneShare(Vec3(-1.0f, 1.1f, 0.5f)), 0.0625f, 1e-5f);          // 0.1 from the point light
  EXPECT_EQ(near.coneShare(onLamp + Vec3(0.0f, -0.41f, 0.0f)), 1.0f);
  EXPECT_EQ(near.coneShare(Vec3(2.0f, 0.0f, 2.0f)), 1.0f);                       // the floor is no light
  // No lamp, only a sun (at infinity): no proximity, every share 1.
  const std::string sunlit = R"({"camera": {"position": [0, 1, -5], "target": [0, 1, 0], "up": [0, 1, 0]},
    "materials": {"floor": {"type": "lambertian", "albedo": 0.5}},
    "shapes": [{"type": "quad", "material": "floor", "vertices": [[-3, 0, -3], [-3, 0, 3], [3, 0, 3], [3, 0, -3]]}],
    "lights": [{"type": "directional", "direction": [0, -1, 0], "irradiance": [1, 1, 1]}]})";
  const LightProximity none(parseScene(sunlit, "sunlit", "."), 0.4f);
  EXPECT_TRUE(none.empty());
  EXPECT_EQ(none.coneShare(Vec3(0.0f)), 1.0f);
}

}  // namespace
}  // namespace voxcone

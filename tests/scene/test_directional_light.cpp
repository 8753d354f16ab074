// The directional light (a delta sun) against closed forms: a Lambertian floor's radiance
// albedo / pi * E cos(theta) in every method, a roof that shadows it wholly, the same radiance
// wherever the scene lies, photons that carry E cos(theta) times the floor's area, and the
// loaders' errors.

#include "voxcone/accel/hbvh.h"
#include "voxcone/core/error.h"
#include "voxcone/photon/photon_tracer.h"
#include "voxcone/scene/mitsuba.h"
#include "voxcone/scene/scene.h"

#include "../support/render_helpers.h"
#include "../support/report.h"
#include "../support/test_scenes.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>
#include <unistd.h>

namespace voxcone {
namespace {

using test::imageMean;
using test::renderWith;
using test::report;
constexpr auto vec = test::jsonVec;


/// A 4 x 4 floor (albedo 0.5) at y = 0 around `at`, seen from 3 above by a camera whose view
/// it fills; the sun travels 60 degrees from straight down (cos 0.5), irradiance (2, 1, 0.5).
/// With `roof`, a 20 x 20 slab at y = 2 hides the floor from the sun.
Scene sunScene(const Vec3& at = Vec3(0.0f), bool roof = false, const std::string& angle = "") {
  const auto quad = [&](float y, float h, const std::string& mat) {
    const Vec3 a = at + Vec3(-h, y, -h), b = at + Vec3(-h, y, h), c = at + Vec3(h, y, h), d = at + Vec3(h, y, -h);
    return R"({"type": "quad", "material": ")" + mat + R"(", "vertices": [)" + vec(a) + "," + vec(b) + "," + vec(c) +
           "," + vec(d) + "]}";
  };
  const std::string json = R"({
    "camera": {"position": )" + vec(at + Vec3(0, 3, 0)) + R"(, "target": )" + vec(at) + R"(, "up": [0, 0, 1],
               "fov_y_deg": 40},
    "render": {"width": 16, "height": 16, "spp": 4, "max_depth": 8},
    "materials": {"floor": {"type": "lambertian", "albedo": 0.5}, "roof": {"type": "lambertian", "albedo": 0}},
    "shapes": [)" + quad(0.0f, 2.0f, "floor") + (roof ? "," + quad(2.0f, 10.0f, "roof") : std::string()) + R"(],
    "lights": [{"type": "directional", "direction": [0.8660254, -0.5, 0], "irradiance": [2, 1, 0.5])" + angle + R"(}]
  })";
  return parseScene(json, "sun-test", ".");
}

TEST(DirectionalLight, AFloorReflectsAlbedoOverPiTimesECosInEveryMethod) {
  // Nothing else in the scene: the floor's radiance is the direct light alone, exactly
  // 0.5 / pi * E * 0.5 (a delta light: no noise), in every method; voxcone's photons are all
  // straight from the sun (its estimate takes only light that bounced).
  const Scene scene = sunScene();
  ASSERT_EQ(scene.directionalLights.size(), 1u);
  ASSERT_EQ(scene.lightCount(), 1u);
  const Vec3 expected = 0.5f / kPi * Vec3(2.0f, 1.0f, 0.5f) * 0.5f;
  // Relative to the expected radiance: the channel nearest its bound, over the methods.
  double worst = -1.0, worstBound = 1.0;
  std::string worstAt;
  for (const char* method : {"path", "whitted", "voxcone", "pm"}) {
    const Vec3 mean = imageMean(renderWith(scene, method, scene.render).image);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(mean[c], expected[c], 1e-4f * expected[c] + 1e-6f) << method << " " << c;
    for (int c = 0; c < 3; ++c) {
      const double off = std::fabs(mean[c] - expected[c]) / expected[c], bound = (1e-4f * expected[c] + 1e-6f) / expected[c];
      if (off / bound > worst / worstBound) {
        worst = off;
        worstBound = bound;
        worstAt = std::string(method) + " channel " + std::to_string(c);
      }
    }
  }
  report("relative error nearest its bound (" + worstAt + ")", worst, worstBound);
}

TEST(DirectionalLight, AFiniteSunGivesTheSameIrradianceByLightAndByBsdfSampling) {
  // angle_deg 20: a disc of radiance E / (pi sin^2 10 deg) within 10 degrees of the axis. Wholly
  // above the floor's horizon (60 + 10 < 90 degrees), its projected solid angle is
  // pi sin^2(10 deg) cos 60 exactly, so the floor shows the delta sun's albedo / pi * E cos 60.
  // Light sampling (path's MIS, whitted, voxcone, pm): a uniform cone, cos varying by +-15%
  // across it; 1% at 4 spp of 16 x 16. BSDF sampling alone must find the disc (1.5% of cosine
  // samples): 1024 spp, about 3,900 hits, 1.6% standard deviation of the mean, 6% bound.
  const Scene scene = sunScene(Vec3(0.0f), false, R"(, "angle_deg": 20)");
  ASSERT_FALSE(scene.directionalLights[0].isDelta());
  const Vec3 expected = 0.5f / kPi * Vec3(2.0f, 1.0f, 0.5f) * 0.5f;
  double worst = -1.0;
  std::string worstAt;
  for (const char* method : {"path", "whitted", "voxcone", "pm"}) {
    const Vec3 mean = imageMean(renderWith(scene, method, scene.render).image);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(mean[c], expected[c], 0.01f * expected[c]) << method << " " << c;
    for (int c = 0; c < 3; ++c)
      if (std::fabs(mean[c] / expected[c] - 1.0f) > worst) {  // the first channel, then any worse
        worst = std::fabs(mean[c] / expected[c] - 1.0f);
        worstAt = std::string(method) + " channel " + std::to_string(c);
      }
  }
  report("light sampling relative error (" + worstAt + ")", worst, 0.01);
  RenderSettings s = scene.render;
  s.spp = 1024;
  const Vec3 bsdf = imageMean(renderWith(scene, "path", s, {{"light_sampling", "none"}}).image);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(bsdf[c], expected[c], 0.06f * expected[c]) << "BSDF sampling " << c;
  double bsdfOff = 0.0;
  for (int c = 0; c < 3; ++c) bsdfOff = std::max(bsdfOff, double(std::fabs(bsdf[c] / expected[c] - 1.0f)));
  report("BSDF sampling relative error, worst channel", bsdfOff, 0.06);
  // A camera ray towards the sun sees its radiance; JSON keeps the angle, Mitsuba refuses it.
  const Vec3 towards = -scene.directionalLights[0].direction;
  const Vec3 L = scene.escaped(towards);
  const double sunL = 2.0f / (kPi * sqr(std::sin(glm::radians(10.0f))));
  report("sun's radiance relative error", std::fabs(L.x - sunL) / L.x, 1e-3);
  EXPECT_NEAR(L.x, 2.0f / (kPi * sqr(std::sin(glm::radians(10.0f)))), 1e-3f * L.x);
  EXPECT_EQ(scene.escaped(glm::normalize(towards + Vec3(0.0f, 0.3f, 0.0f))), Vec3(0.0f));  // 17 degrees off
}

TEST(DirectionalLight, ARoofHidesTheFloorAndMovingTheSceneChangesNothing) {
  const Vec3 expected = 0.5f / kPi * Vec3(2.0f, 1.0f, 0.5f) * 0.5f;
  const Scene roofed = sunScene(Vec3(0.0f), true);
  EXPECT_EQ(imageMean(renderWith(roofed, "path", roofed.render).image), Vec3(0.0f));
  EXPECT_EQ(imageMean(renderWith(roofed, "voxcone", roofed.render).image), Vec3(0.0f));
  // Far from the origin (as far as the loader lets a scene 4 across lie) the shadow rays cross
  // as long a scene: the same radiance (float rounding of coordinates near 900 only).
  const Scene moved = sunScene(Vec3(-612.0f, 275.0f, 903.0f));
  const Vec3 mean = imageMean(renderWith(moved, "path", moved.render).image);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(mean[c], expected[c], 1e-3f * expected[c]) << c;
  double off = 0.0;
  for (int c = 0; c < 3; ++c) off = std::max(off, double(std::fabs(mean[c] / expected[c] - 1.0f)));
  report("moved scene relative error, worst channel", off, 1e-3);
}

TEST(DirectionalLight, PhotonsCarryECosTimesTheFloorsArea) {
  // Every photon leaves a disc across the sun that covers the bounding sphere, carrying
  // E pi R^2 / N; the floor (16 m^2) receives E cos(theta) 16 = 16 W in red. A photon lands on
  // it with probability p = 16 * 0.5 / (pi R^2): 5 sigma of the binomial count.
  const Scene scene = sunScene();
  const Hbvh accel(scene);
  const PhotonSettings s = test::photonSettings(200000, 0);
  const PhotonMaps maps = tracePhotons(scene, accel, s);
  double red = 0.0;
  for (const Photon& p : maps.global) red += p.power.x;
  const double r = scene.boundingSphere().radius;
  const double p = 16.0 * 0.5 / (kPi * r * r);
  const double n = double(s.photons);
  report("floor's power - 16 W", std::fabs(red - 16.0), 5.0 * 16.0 * std::sqrt((1.0 - p) / (n * p)));
  report("emitted power relative error", std::fabs(maps.stats.emittedPower.x / (2.0 * kPi * r * r) - 1.0), 1e-3);
  EXPECT_NEAR(red, 16.0, 5.0 * 16.0 * std::sqrt((1.0 - p) / (n * p)));
  EXPECT_NEAR(maps.stats.emittedPower.x, 2.0 * kPi * r * r, 1e-3 * 2.0 * kPi * r * r);
  // Each photon arrives from the sun.
  float worst = 0.0f;
  for (size_t i = 0; i < maps.global.size(); i += 101) {
    EXPECT_NEAR(glm::dot(maps.global[i].incident, Vec3(-0.8660254f, 0.5f, 0.0f)), 1.0f, 1e-5f);
    worst = std::max(worst, std::fabs(glm::dot(maps.global[i].incident, Vec3(-0.8660254f, 0.5f, 0.0f)) - 1.0f));
  }
  report("worst 1 - cos(incident, sun)", worst, 1e-5);
}

TEST(DirectionalLight, PhotonsAimedAtWhatTheCameraReadsCarryTheSameFlux) {
  // distant_aim: three quarters of the photons leave the disc of a 0.5 m sphere around a point
  // of the floor, the rest the whole disc, each weighted by the mixture's density at its point.
  // The floor still receives E cos(theta) 16 = 16 W in red (5 sigma of the photons' own
  // spread), while the tube of the target now holds most photons instead of 3% of them.
  const Scene scene = sunScene();
  const Hbvh accel(scene);
  const Vec3 d = glm::normalize(Vec3(0.8660254f, -0.5f, 0.0f));
  const Sphere target{Vec3(1.0f, 0.0f, 1.0f), 0.5f};
  const auto inTube = [&](const Vec3& p) {
    const Vec3 off = p - target.center;
    return glm::length(off - d * glm::dot(off, d)) < target.radius;
  };
  PhotonSettings s = test::photonSettings(200000, 0);
  const PhotonMaps blind = tracePhotons(scene, accel, s);
  s.distantTarget = target;
  s.distantShare = 0.75;
  const PhotonMaps aimed = tracePhotons(scene, accel, s);
  double red = 0.0, redSq = 0.0;
  size_t aimedIn = 0, blindIn = 0;
  for (const Photon& p : aimed.global) {
    red += p.power.x;
    redSq += double(p.power.x) * double(p.power.x);
    aimedIn += inTube(p.position) ? 1 : 0;
  }
  for (const Photon& p : blind.global) blindIn += inTube(p.position) ? 1 : 0;
  const double n = double(s.photons), sigma = std::sqrt(std::max(redSq - red * red / n, 0.0));
  report("floor's power - 16 W", std::fabs(red - 16.0), 5.0 * sigma);
  report("sigma", sigma, 0.2);
  EXPECT_NEAR(red, 16.0, 5.0 * sigma);
  EXPECT_LT(sigma, 0.2);
  const double r = scene.boundingSphere().radius, tubeShare = 0.25 / (r * r);
  report("aimed photons' share in the tube (lower bound)", double(aimedIn) / n, 0.9 * (0.75 + 0.25 * tubeShare));
  report("blind photons' share in the tube", double(blindIn) / n, 1.2 * tubeShare);
  EXPECT_GT(double(aimedIn), 0.9 * (0.75 + 0.25 * tubeShare) * n);
  EXPECT_LT(double(blindIn), 1.2 * tubeShare * n);
  // A target as large as the scene's sphere changes nothing.
  s.distantTarget = Sphere{scene.boundingSphere().center, float(r)};
  const PhotonMaps whole = tracePhotons(scene, accel, s);
  ASSERT_EQ(whole.global.size(), blind.global.size());
  for (size_t i = 0; i < whole.global.size(); i += 97) EXPECT_EQ(whole.global[i].position, blind.global[i].position);
}

TEST(DirectionalLight, BadLightsAreOneLineErrors) {
  const auto errorOf = [](const std::string& light) {
    const std::string json = R"({
      "camera": {"position": [0, 3, 0], "target": [0, 0, 0], "up": [0, 0, 1]},
      "materials": {"floor": {"type": "lambertian", "albedo": 0.5}},
      "shapes": [{"type": "quad", "material": "floor", "vertices": [[-1, 0, -1], [-1, 0, 1], [1, 0, 1], [1, 0, -1]]}],
      "lights": [)" + light + R"(]
    })";
    try {
      parseScene(json, "bad.json", ".");
    } catch (const SceneError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_NE(errorOf(R"({"type": "directional", "direction": [0, 0, 0], "irradiance": 1})").find("non-zero"),
            std::string::npos);
  EXPECT_NE(errorOf(R"({"type": "directional", "irradiance": 1})").find("direction"), std::string::npos);
  EXPECT_NE(errorOf(R"({"type": "directional", "direction": [0, -1, 0], "irradiance": -1})").find("irradiance"),
            std::string::npos);
  EXPECT_NE(errorOf(R"({"type": "directional", "direction": [0, -1, 0], "irradiance": 1, "angle_deg": 100})")
                .find("angle_deg"),
            std::string::npos);
  EXPECT_EQ(errorOf(R"({"type": "directional", "direction": [0, -1, 0], "irradiance": 1, "angle_deg": 0.53})"), "");
  EXPECT_NE(errorOf(R"({"type": "directional", "direction": [0, -1, 0], "irradiance": 1, "size": 2})").find("size"),
            std::string::npos);
  // angle_deg 0 is the delta light.
  EXPECT_EQ(errorOf(R"({"type": "directional", "direction": [0, -1, 0], "irradiance": 1, "angle_deg": 0})"), "");
}

TEST(DirectionalLight, MitsubaDirectionalEmitter) {
  const std::string head = R"(<?xml version="1.0"?>
<scene version="3.0.0">
  <sensor type="perspective"><float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0, 3, 0" target="0, 0, 0" up="0, 0, 1"/></transform>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film></sensor>
  <shape type="rectangle"><transform name="to_world"><rotate x="1" angle="-90"/></transform></shape>
)";
  const Scene a = parseMitsubaScene(head + R"(<emitter type="directional"><vector name="direction" value="0, -2, 0"/>
    <rgb name="irradiance" value="3, 2, 1"/></emitter></scene>)", "a.xml", ".");
  ASSERT_EQ(a.directionalLights.size(), 1u);
  report("direction.y + 1", std::fabs(a.directionalLights[0].direction.y + 1.0f), 1e-6);
  EXPECT_NEAR(a.directionalLights[0].direction.y, -1.0f, 1e-6f);
  EXPECT_EQ(a.directionalLights[0].irradiance, Vec3(3.0f, 2.0f, 1.0f));
  // to_world turns +z: 90 degrees about x sends it to -y.
  const Scene b = parseMitsubaScene(head + R"(<emitter type="directional"><transform name="to_world">
    <rotate x="1" angle="90"/></transform></emitter></scene>)", "b.xml", ".");
  ASSERT_EQ(b.directionalLights.size(), 1u);
  report("turned direction.y + 1", std::fabs(b.directionalLights[0].direction.y + 1.0f), 1e-5);
  EXPECT_NEAR(b.directionalLights[0].direction.y, -1.0f, 1e-5f);
  EXPECT_EQ(b.directionalLights[0].irradiance, Vec3(1.0f));
  EXPECT_THROW(parseMitsubaScene(head + R"(<emitter type="directional"><vector name="direction" value="0, 0, 0"/>
    </emitter></scene>)", "c.xml", "."), SceneError);
}

TEST(DirectionalLight, ConvertWritesItBothWays) {
  // JSON -> Mitsuba XML -> JSON keeps the light.
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("voxcone-sun-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const Scene scene = sunScene();
  writeMitsubaScene(scene, (dir / "sun.xml").string());
  const Scene xml = loadScene((dir / "sun.xml").string());
  writeJsonScene(xml, (dir / "sun.json").string());
  const Scene back = loadScene((dir / "sun.json").string());
  float worst = 0.0f;
  for (const Scene* s : {&xml, &back}) {
    ASSERT_EQ(s->directionalLights.size(), 1u);
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(s->directionalLights[0].direction[c], scene.directionalLights[0].direction[c], 1e-6f);
      EXPECT_NEAR(s->directionalLights[0].irradiance[c], scene.directionalLights[0].irradiance[c], 1e-6f);
      worst = std::max({worst, std::fabs(s->directionalLights[0].direction[c] - scene.directionalLights[0].direction[c]),
                        std::fabs(s->directionalLights[0].irradiance[c] - scene.directionalLights[0].irradiance[c])});
    }
  }
  report("worst direction or irradiance error", worst, 1e-6);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace voxcone

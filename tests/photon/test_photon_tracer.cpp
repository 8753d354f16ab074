// Photon tracing against analytic answers: emitted flux, power conservation under Russian
// roulette, irradiance of a point light on a plane, the caustic / global split, determinism
// across thread counts (Jensen 2001, ch. 5).
//
// Statistical bounds are stated per test as a multiple of the standard deviation derived for
// that estimator, so a failure means a bias, not bad luck (5 sigma: about 1 in 3.5 million).

#include "voxcone/photon/photon_tracer.h"

#include "voxcone/accel/hbvh.h"
#include "voxcone/core/error.h"
#include "voxcone/core/parallel.h"
#include "voxcone/scene/scene.h"

#include "../support/test_scenes.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstdio>
#include <cstring>

namespace voxcone {
namespace {

/// A scene from JSON fragments, with a camera that the tracer ignores.
Scene makeScene(const std::string& materials, const std::string& shapes, const std::string& lights) {
  const std::string json = R"({
    "camera": {"position": [0, 0.5, -10], "target": [0, 0.5, 0], "up": [0, 1, 0]},
    "materials": {)" + materials + R"(},
    "shapes": [)" + shapes + R"(],
    "lights": [)" + lights + R"(]
  })";
  return parseScene(json, "photon-test", ".");
}

/// A horizontal quad at height y, half-size h, centred on the y axis; normal +y when `up`.
std::string hquad(float y, float h, const std::string& material, bool up) {
  const std::string Y = std::to_string(y), P = std::to_string(h), N = std::to_string(-h);
  const std::string a = "[" + N + "," + Y + "," + N + "]", b = "[" + P + "," + Y + "," + N + "]",
                    c = "[" + P + "," + Y + "," + P + "]", d = "[" + N + "," + Y + "," + P + "]";
  // (a, b, c) winds to -y; the reverse order to +y.
  const std::string verts = up ? a + "," + d + "," + c + "," + b : a + "," + b + "," + c + "," + d;
  return R"({"type": "quad", "material": ")" + material + R"(", "vertices": [)" + verts + "]}";
}

using test::photonSettings;

DVec3 totalPower(const std::vector<Photon>& photons) {
  DVec3 s(0.0);
  for (const Photon& p : photons) s += DVec3(p.power);
  return s;
}

double horizontalRadius(const Vec3& p) { return std::sqrt(double(p.x) * p.x + double(p.z) * p.z); }

// ---------------------------------------------------------------------------------------------
// Emission

TEST(PhotonEmission, CornellBoxFluxIsPiLeArea) {
  // The Cornell light: Le = (17, 12, 4) on a 130 x 105 quad, one-sided: flux pi Le A.
  const Scene scene = loadScene(test::sourceDir() + "/data/scenes/cornell-box.json");
  const Hbvh accel(scene);
  const PhotonMaps maps = tracePhotons(scene, accel, photonSettings(20000, 0));
  const DVec3 expected = double(kPi) * DVec3(17.0, 12.0, 4.0) * (130.0 * 105.0);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(maps.stats.emittedPower[c], expected[c], 1e-4 * expected[c]) << c;
  EXPECT_EQ(maps.stats.emittedGlobal, 20000u);
  EXPECT_EQ(maps.stats.storedGlobal, maps.global.size());
  // Closed box, albedo-0 light: every photon lands at least once on a diffuse surface
  // (all surfaces are diffuse), so at least as many photons as emitted are stored.
  EXPECT_GE(maps.global.size(), 20000u);
}

TEST(PhotonEmission, AbsorbingSphereStoresPointLightFluxOnce) {
  // Albedo 0: every photon is stored exactly once at its first hit and then absorbed, so the
  // stored total is the emitted flux 4 pi I, up to float rounding of the per-photon power.
  const float intensity = 3.0f;
  const Scene scene = test::furnaceScene(0.0f, 0.0f, intensity, 3);
  const Hbvh accel(scene);
  const uint64_t n = 50000;
  const PhotonMaps maps = tracePhotons(scene, accel, photonSettings(n, 0));
  ASSERT_EQ(maps.global.size(), n);
  const double flux = 4.0 * kPi * intensity;
  const DVec3 sum = totalPower(maps.global);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(sum[c], flux, 1e-5 * flux) << c;
  for (const Photon& p : maps.global) EXPECT_NEAR(glm::length(p.position), 1.0f, 0.02f);
}

TEST(PhotonEmission, AbsorbingSphereStoresColouredPatchFluxOnce) {
  // A one-sided emissive quad of Le = (17, 12, 4) (not grey) inside an absorbing sphere: the
  // RGB flux pi Le A arrives exactly, channel by channel. Both triangles have one chromaticity,
  // so every photon carries exactly flux / N.
  const Scene scene = makeScene(
      R"("wall": {"type": "lambertian", "albedo": 0}, "lamp": {"type": "lambertian", "albedo": 0, "emission": [17, 12, 4]})",
      R"({"type": "sphere", "center": [0, 0, 0], "radius": 2, "subdivisions": 3, "material": "wall"},)" +
          hquad(0.0f, 0.25f, "lamp", false),
      "");
  const Hbvh accel(scene);
  const uint64_t n = 50000;
  const PhotonMaps maps = tracePhotons(scene, accel, photonSettings(n, 0));
  const DVec3 flux = double(kPi) * DVec3(17.0, 12.0, 4.0) * 0.25;
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(maps.stats.emittedPower[c], flux[c], 1e-5 * flux[c]);
  ASSERT_EQ(maps.global.size(), n);
  const DVec3 sum = totalPower(maps.global);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(sum[c], flux[c], 1e-5 * flux[c]) << c;
  // Emitted downwards only: every photon lands on the lower half of the sphere.
  for (const Photon& p : maps.global) EXPECT_LT(p.position.y, 0.0f);
}

TEST(PhotonEmission, MixedColourLightsCarryExpectedFluxPerChannel) {
  // A red point light and a blue emissive patch: the light is chosen by luminance, each photon
  // carries flux_i / pmf_i / N, so the red total is (n_red / N) flux_red / pmf_red. The choice
  // is stratified over the pass, so n_red is N pmf_red to within one photon (independent
  // choices would make it binomial, off by about sqrt(N p (1 - p)) = 130 photons here): the
  // total within one photon's power, 1 / (N pmf), plus float rounding. Blue likewise.
  const Scene scene = makeScene(
      R"("wall": {"type": "lambertian", "albedo": 0}, "lamp": {"type": "lambertian", "albedo": 0, "emission": [0, 0, 20]})",
      R"({"type": "sphere", "center": [0, 0, 0], "radius": 2, "subdivisions": 3, "material": "wall"},)" +
          hquad(-0.5f, 0.25f, "lamp", false),
      R"({"type": "point", "position": [0, 0.5, 0], "intensity": [1, 0, 0]})");
  const Hbvh accel(scene);
  const uint64_t n = 100000;
  const PhotonMaps maps = tracePhotons(scene, accel, photonSettings(n, 0));
  const double red = 4.0 * kPi, blue = kPi * 20.0 * 0.25;
  const double pRed = 0.2126 * red / (0.2126 * red + 0.0722 * blue);
  const DVec3 sum = totalPower(maps.global);
  EXPECT_NEAR(maps.stats.emittedPower.x, red, 1e-5 * red);
  EXPECT_NEAR(maps.stats.emittedPower.z, blue, 1e-5 * blue);
  EXPECT_EQ(sum.y, 0.0);
  EXPECT_NEAR(sum.x, red, red * (1.0 / (n * pRed) + 1e-5));
  EXPECT_NEAR(sum.z, blue, blue * (1.0 / (n * (1.0 - pRed)) + 1e-5));
  // Each photon is all red or all blue.
  for (const Photon& p : maps.global) EXPECT_TRUE(p.power.x == 0.0f || p.power.z == 0.0f);
}

TEST(PhotonEmission, TheLampsAloneLeaveTheSkyAndTheSunOut) {
  // The red point light and blue patch of the test above, and outside the absorbing sphere a
  // green sky (radiance 1 all round: flux pi R^2 4 pi, R the scene's bounding sphere's) and a
  // green sun. With localOnly the pass carries the lamps' flux alone, channel by channel, and
  // not one photon has green; lampPhotonShare is the lamps' share of the luminance of flux.
  const Scene scene = makeScene(
      R"("wall": {"type": "lambertian", "albedo": 0}, "lamp": {"type": "lambertian", "albedo": 0, "emission": [0, 0, 20]})",
      R"({"type": "sphere", "center": [0, 0, 0], "radius": 2, "subdivisions": 3, "material": "wall"},)" +
          hquad(-0.5f, 0.25f, "lamp", false),
      R"({"type": "point", "position": [0, 0.5, 0], "intensity": [1, 0, 0]},
         {"type": "environment", "radiance": [0, 1, 0]},
         {"type": "directional", "direction": [0, -1, 0], "irradiance": [0, 2, 0]})");
  const Hbvh accel(scene);
  PhotonSettings s = photonSettings(50000, 0);
  s.localOnly = true;
  const PhotonMaps maps = tracePhotons(scene, accel, s);
  const double red = 4.0 * kPi, blue = kPi * 20.0 * 0.25;
  EXPECT_NEAR(maps.stats.emittedPower.x, red, 1e-5 * red);
  EXPECT_EQ(maps.stats.emittedPower.y, 0.0f);
  EXPECT_NEAR(maps.stats.emittedPower.z, blue, 1e-5 * blue);
  ASSERT_GT(maps.global.size(), 0u);
  for (const Photon& p : maps.global) ASSERT_EQ(p.power.y, 0.0f);
  const double R = scene.boundingSphere().radius;
  const double green = kPi * R * R * 4.0 * kPi + 2.0 * kPi * R * R;
  const double lamps = 0.2126 * red + 0.0722 * blue;
  EXPECT_NEAR(lampPhotonShare(scene), lamps / (lamps + 0.7152 * green), 1e-6);
}

TEST(PhotonEmission, OneAndTwoSidedEmitters) {
  // An emitter at y = 1 facing down between an absorbing floor (y = 0) and ceiling (y = 2):
  // one-sided, every stored photon is on the floor; two-sided, the flux doubles and each side
  // gets half (the side is a fair coin: binomial bound on the floor's count).
  for (bool twoSided : {false, true}) {
    const Scene scene = makeScene(
        R"("wall": {"type": "lambertian", "albedo": 0}, "lamp": {"type": "lambertian", "albedo": 0, "emission": 2, "two_sided_emission": )" +
            std::string(twoSided ? "true" : "false") + "}",
        hquad(0.0f, 1000.0f, "wall", true) + "," + hquad(2.0f, 1000.0f, "wall", false) + "," +
            hquad(1.0f, 0.5f, "lamp", false),
        "");
    const Hbvh accel(scene);
    const uint64_t n = 40000;
    const PhotonMaps maps = tracePhotons(scene, accel, photonSettings(n, 0));
    const double flux = kPi * 2.0 * 1.0 * (twoSided ? 2.0 : 1.0);
    EXPECT_NEAR(maps.stats.emittedPower.x, flux, 1e-5 * flux);
    uint64_t floorCount = 0;
    for (const Photon& p : maps.global) {
      floorCount += p.position.y < 0.5f;
      // The normal faces the side the photon came from.
      EXPECT_NEAR(p.normal.y, p.position.y < 0.5f ? 1.0f : -1.0f, 1e-6f);
    }
    // Grazing photons (about 1e-6 of them) may escape between the planes' far edges.
    EXPECT_NEAR(double(maps.global.size()), double(n), 1e-3 * n);
    if (!twoSided) {
      EXPECT_EQ(floorCount, maps.global.size());
    } else {
      EXPECT_NEAR(double(floorCount), 0.5 * n, 5.0 * std::sqrt(0.25 * n));
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Tracing

TEST(PhotonTracer, RussianRouletteConservesPowerInClosedSphere) {
  // A point light inside a closed sphere of albedo a: each photon deposits its power at every
  // hit and survives with the albedo, so the expected stored total is flux (1 + a + a^2 ...)
  // = flux / (1 - a), per channel with a per-channel albedo.
  // Bound: the survival probability is the largest albedo (0.8), so a photon's green total is
  // its power times a geometric count of mean 5 and variance 20: relative std. dev. of the sum
  // 0.9 / sqrt(N) = 0.2% at N = 200000. Red and blue vary less (their sums are bounded). The
  // 1% bound is 5 sigma. maxDepth 200 truncates a fraction 0.8^200 of the path.
  const Scene scene = makeScene(R"("wall": {"type": "lambertian", "albedo": [0.5, 0.8, 0.2]})",
                                R"({"type": "sphere", "center": [0, 0, 0], "radius": 1, "subdivisions": 3, "material": "wall"})",
                                R"({"type": "point", "position": [0.1, 0.2, -0.1], "intensity": 1})");
  const Hbvh accel(scene);
  const uint64_t n = 200000;
  const PhotonMaps maps = tracePhotons(scene, accel, photonSettings(n, 0, 200));
  const double flux = 4.0 * kPi;
  const DVec3 albedo(0.5, 0.8, 0.2);
  const DVec3 sum = totalPower(maps.global);
  for (int c = 0; c < 3; ++c) {
    const double expected = flux / (1.0 - albedo[c]);
    EXPECT_NEAR(sum[c], expected, 0.01 * expected) << "channel " << c;
  }
  // Stored count: geometric with survival 0.8, mean N / 0.2 (same 5-sigma bound).
  EXPECT_NEAR(double(maps.global.size()), n / 0.2, 0.01 * n / 0.2);
  EXPECT_TRUE(maps.caustic.empty());
}

TEST(PhotonTracer, GreyFurnaceKeepsPhotonPowerConstant) {
  // Grey albedo 0.5: survival 0.5 and division by it leave every stored photon with exactly
  // the emitted flux / N, and the total is flux / (1 - a) = 2 flux (5 sigma: 1.6%).
  const Scene scene = test::furnaceScene(0.5f, 0.0f, 1.0f, 3);
  const Hbvh accel(scene);
  const uint64_t n = 50000;
  const PhotonMaps maps = tracePhotons(scene, accel, photonSettings(n, 0, 200));
  const float perPhoton = float(4.0 * kPi / n);
  for (const Photon& p : maps.global) ASSERT_NEAR(p.power.y, perPhoton, 1e-5f * perPhoton);
  const DVec3 sum = totalPower(maps.global);
  EXPECT_NEAR(sum.y, 2.0 * 4.0 * kPi, 5.0 * 0.707 / std::sqrt(double(n)) * 2.0 * 4.0 * kPi);
}

using test::rectangleSolidAngle;

TEST(PhotonTracer, PointLightIrradianceOnPlane) {
  // A point light of intensity I at height h = 1 above an absorbing plane: the flux through a
  // patch is I times its solid angle (the integral of E = I cos / r^2 over the patch). The
  // photons on a patch are binomial with p = Omega / (4 pi): 5-sigma bound on the count.
  const float intensity = 2.0f;
  const Scene scene = makeScene(R"("floor": {"type": "lambertian", "albedo": 0})", hquad(0.0f, 100.0f, "floor", false),
                                R"({"type": "point", "position": [0, 1, 0], "intensity": 2})");
  const Hbvh accel(scene);
  const uint64_t n = 1000000;
  const PhotonMaps maps = tracePhotons(scene, accel, photonSettings(n, 0));
  struct Patch {
    double x0, x1, z0, z1;
  };
  // Under the light (cos/r^2 = 1) and off axis at x = 1 (cos/r^2 = 2^-1.5).
  for (const Patch& pa : {Patch{-0.2, 0.2, -0.2, 0.2}, Patch{0.8, 1.2, -0.2, 0.2}}) {
    double power = 0.0;
    uint64_t count = 0;
    for (const Photon& p : maps.global) {
      if (p.position.x >= pa.x0 && p.position.x < pa.x1 && p.position.z >= pa.z0 && p.position.z < pa.z1) {
        power += p.power.x;
        ++count;
      }
    }
    const double omega = rectangleSolidAngle(pa.x0, pa.x1, pa.z0, pa.z1, 1.0);
    const double p = omega / (4.0 * kPi);
    const double expected = intensity * omega;
    EXPECT_NEAR(power, expected, 5.0 * expected * std::sqrt((1.0 - p) / (n * p))) << pa.x0;
    // The irradiance at the patch centre, E = I cos / r^2, matches the mean density to within
    // the curvature of E over the patch (0.4 wide: under 6%).
    const double xc = 0.5 * (pa.x0 + pa.x1);
    const double e = intensity * 1.0 / std::pow(xc * xc + 1.0, 1.5);
    EXPECT_NEAR(power / ((pa.x1 - pa.x0) * (pa.z1 - pa.z0)), e, 0.06 * e) << pa.x0;
    EXPECT_GT(count, 4000u);
  }
  // Photon geometry: incident points back to the light, the normal faces it.
  for (size_t i = 0; i < maps.global.size(); i += 97) {
    const Photon& p = maps.global[i];
    EXPECT_NEAR(p.position.y, 0.0f, 1e-5f);
    EXPECT_NEAR(glm::dot(p.incident, glm::normalize(Vec3(0, 1, 0) - p.position)), 1.0f, 1e-4f);
    EXPECT_NEAR(p.normal.y, 1.0f, 1e-6f);
  }
  // The plane (200 x 200) catches the photons in its solid angle (a hemisphere less 1%).
  const double pPlane = rectangleSolidAngle(-100.0, 100.0, -100.0, 100.0, 1.0) / (4.0 * kPi);
  EXPECT_NEAR(double(maps.global.size()), pPlane * n, 5.0 * std::sqrt(pPlane * (1.0 - pPlane) * n));
}

// ---------------------------------------------------------------------------------------------
// Caustics

/// A glass sphere (radius 1 at height 2) over a large floor, a point light at height 5.
Scene glassScene(float floorAlbedo, const std::string& sphereMaterial = R"({"type": "dielectric", "ior": 1.5})") {
  return makeScene(R"("floor": {"type": "lambertian", "albedo": )" + std::to_string(floorAlbedo) + R"(}, "glass": )" +
                       sphereMaterial,
                   hquad(0.0f, 50.0f, "floor", true) +
                       R"(, {"type": "sphere", "center": [0, 2, 0], "radius": 1, "subdivisions": 4, "material": "glass"})",
                   R"({"type": "point", "position": [0, 5, 0], "intensity": 10})");
}

TEST(PhotonCaustics, GlassSphereFocusesCausticsUnderIt) {
  // Floor albedo 0: the global map holds only direct photons (L D), the caustic map only
  // L S+ D photons. The sphere's shadow from the light has radius 5 tan(asin(1/3)) = 1.77.
  const Scene scene = glassScene(0.0f);
  const Hbvh accel(scene);
  const uint64_t n = 100000;
  const PhotonMaps maps = tracePhotons(scene, accel, photonSettings(n, n));
  ASSERT_GT(maps.caustic.size(), 1000u);
  const float perPhoton = float(4.0 * kPi * 10.0 / n);
  // No global photon in the shadow (they would be L S+ D); all carry the unbounced power.
  for (const Photon& p : maps.global) {
    ASSERT_GT(horizontalRadius(p.position), 1.70);
    ASSERT_EQ(p.power.x, perPhoton);
  }
  // Every caustic photon is on the floor (the only diffuse surface), and its power is at most
  // the emitted one: specular weights (Fresnel, transmission) are <= 1 and take no roulette.
  double inShadow = 0.0, total = 0.0, core = 0.0;
  for (const Photon& p : maps.caustic) {
    ASSERT_NEAR(p.position.y, 0.0f, 1e-4f);
    ASSERT_LE(p.power.x, perPhoton * (1.0f + 1e-5f));
    total += p.power.x;
    const double r = horizontalRadius(p.position);
    if (r < 1.77) inShadow += p.power.x;
    if (r < 0.5) core += p.power.x;
  }
  // Most caustic power is refracted through the sphere into its shadow (the rest is Fresnel
  // reflection thrown sideways).
  EXPECT_GT(inShadow, 0.8 * total);
  // Focusing: the caustic core (r < 0.5) is brighter than the direct irradiance would be
  // there without the sphere (E = I / 5^2 = 0.4).
  EXPECT_GT(core / (kPi * 0.25), 0.4);
  EXPECT_EQ(maps.stats.storedCaustic, maps.caustic.size());
  EXPECT_EQ(maps.stats.emittedCaustic, n);
}

TEST(PhotonCaustics, AimedCausticPhotonsCarryTheSameFluxAsUnaimedOnes) {
  // Caustic photons aimed at the specular triangles' bounding sphere (the default) against
  // photons over the whole emission distribution: the caustic map's power, in all and in the
  // caustic's core, agrees within the unaimed map's noise, from many times more stored photons.
  // A point light (above) and a one-sided emissive quad facing down (the area light).
  const std::string glass = R"("floor": {"type": "lambertian", "albedo": 0}, "glass": {"type": "dielectric", "ior": 1.5},
                               "lamp": {"type": "lambertian", "albedo": 0, "emission": 20})";
  const std::string shapes =
      hquad(0.0f, 50.0f, "floor", true) +
      R"(, {"type": "sphere", "center": [0, 2, 0], "radius": 1, "subdivisions": 4, "material": "glass"})";
  const Scene scenes[2] = {glassScene(0.0f), makeScene(glass, shapes + ", " + hquad(5.0f, 0.5f, "lamp", false), "")};
  for (const Scene& scene : scenes) {
    const Hbvh accel(scene);
    PhotonSettings aimed = photonSettings(0, 200000), plain = aimed;
    plain.aimCaustics = false;
    const PhotonMaps a = tracePhotons(scene, accel, aimed), b = tracePhotons(scene, accel, plain);
    ASSERT_GT(b.caustic.size(), 2000u);
    // Measured: 55,702 against 5,097 stored (point light), 55,900 against 19,499 (the quad,
    // whose cosine lobe already points at the sphere); power ratios 1.003 and 0.994.
    EXPECT_GT(a.caustic.size(), 2 * b.caustic.size());
    const auto core = [](const std::vector<Photon>& photons) {
      double sum = 0.0;
      for (const Photon& p : photons) sum += horizontalRadius(p.position) < 0.5 ? double(p.power.x) : 0.0;
      return sum;
    };
    EXPECT_NEAR(totalPower(a.caustic).x / totalPower(b.caustic).x, 1.0, 0.03);
    EXPECT_NEAR(core(a.caustic) / core(b.caustic), 1.0, 0.05);
  }
}

TEST(PhotonCaustics, NoSpecularMaterialsGiveNoCausticPhotons) {
  // Cornell box: all diffuse. The same glass scene with a rough dielectric sphere: rough
  // bounces are not specular, so no path is L S+ D.
  {
    const Scene scene = loadScene(test::sourceDir() + "/data/scenes/cornell-box.json");
    const Hbvh accel(scene);
    const PhotonMaps maps = tracePhotons(scene, accel, photonSettings(5000, 20000));
    EXPECT_TRUE(maps.caustic.empty());
    EXPECT_EQ(maps.stats.storedCaustic, 0u);
    EXPECT_EQ(maps.stats.emittedCaustic, 20000u);
  }
  {
    const Scene scene = glassScene(0.5f, R"({"type": "rough_dielectric", "ior": 1.5, "roughness": 0.3})");
    const Hbvh accel(scene);
    const PhotonMaps maps = tracePhotons(scene, accel, photonSettings(20000, 20000));
    EXPECT_TRUE(maps.caustic.empty());
    // Light through the rough sphere reaches its shadow in the global map instead.
    size_t inShadow = 0;
    for (const Photon& p : maps.global) inShadow += horizontalRadius(p.position) < 1.5;
    EXPECT_GT(inShadow, 100u);
  }
}

TEST(PhotonCaustics, GlobalMapExcludesCausticPaths) {
  // With a white floor the glass scene's shadow core still receives only L S+ D light and
  // L D S* D light; the second needs a diffuse bounce on the floor and a way back through the
  // sphere. The caustic pass must see the first; the global pass must hold much less power
  // in the core than the caustic map (it would hold about as much if it kept L S+ D).
  const Scene scene = glassScene(0.8f);
  const Hbvh accel(scene);
  const uint64_t n = 100000;
  const PhotonMaps maps = tracePhotons(scene, accel, photonSettings(n, n));
  double globalCore = 0.0, causticCore = 0.0;
  for (const Photon& p : maps.global)
    if (horizontalRadius(p.position) < 0.5) globalCore += p.power.x;
  for (const Photon& p : maps.caustic)
    if (horizontalRadius(p.position) < 0.5) causticCore += p.power.x;
  EXPECT_GT(causticCore, 0.0);
  EXPECT_LT(globalCore, 0.1 * causticCore);
}

TEST(PhotonCaustics, GlossySurfacesKeepTheLightMirrorsSendThem) {
  // A point light (I = 1) 1 above a 0.5 x 0.5 aluminium mirror inside a closed sphere of rough
  // aluminium (roughness 0.3, glossy): the caustic pass's photons that the mirror reflects end
  // on the sphere (L S G), each kept once where it lands, so their total is the flux the mirror
  // reflects, I * Omega * R, Omega the mirror's solid angle from the light and R aluminium's
  // reflectance (red 0.928 at normal incidence, Fresnel with eta 1.657, k 9.224; within 1% up to
  // the 20 degrees here). Photons straight from the light (missing the mirror) keep nothing.
  // Bound: 4% (binomial noise of which aimed photons meet the mirror: 0.6% standard deviation).
  const std::string al = R"({"type": "rough_conductor", "eta": [1.657, 0.880, 0.521], "k": [9.224, 6.270, 4.837], "roughness": 0.3})";
  const std::string mirror = R"({"type": "conductor", "eta": [1.657, 0.880, 0.521], "k": [9.224, 6.270, 4.837]})";
  const Scene scene = makeScene(R"("wall": )" + al + R"(, "mirror": )" + mirror,
                                R"({"type": "sphere", "center": [0, 0, 0], "radius": 2, "subdivisions": 4, "material": "wall"},)" +
                                    hquad(-0.5f, 0.25f, "mirror", true),
                                R"({"type": "point", "position": [0, 0.5, 0], "intensity": 1})");
  const Hbvh accel(scene);
  const PhotonMaps maps = tracePhotons(scene, accel, photonSettings(1000, 20000));
  EXPECT_TRUE(maps.global.empty());  // nothing diffuse
  EXPECT_TRUE(maps.caustic.empty());
  ASSERT_GT(maps.glossyCaustic.size(), 5000u);
  EXPECT_EQ(maps.stats.storedGlossyCaustic, maps.glossyCaustic.size());
  for (const Photon& p : maps.glossyCaustic) {
    EXPECT_NEAR(glm::length(p.position), 2.0f, 0.02f);
    EXPECT_GT(p.position.y, -0.5f);  // reflected upwards
    EXPECT_EQ(p.bounces, 1);
  }
  const double omega = test::rectangleSolidAngle(-0.25, 0.25, -0.25, 0.25, 1.0);
  const double ratio = totalPower(maps.glossyCaustic).x / (omega * 0.928);
  std::printf("glossy caustic photons: %zu, red power / (I Omega R) = %.4f\n", maps.glossyCaustic.size(), ratio);
  EXPECT_NEAR(ratio, 1.0, 0.04);
}

// ---------------------------------------------------------------------------------------------
// Determinism, edge cases, progress

/// Field by field: Photon has padding bytes, which a memcmp compared too (indeterminate: the
/// sanitizer build's differed between two identical maps).
bool samePhotons(const std::vector<Photon>& a, const std::vector<Photon>& b) {
  if (a.size() != b.size()) return false;
  auto same = [](const Vec3& x, const Vec3& y) { return std::memcmp(&x, &y, sizeof(Vec3)) == 0; };
  for (size_t i = 0; i < a.size(); ++i)
    if (!same(a[i].position, b[i].position) || !same(a[i].power, b[i].power) || !same(a[i].incident, b[i].incident) ||
        !same(a[i].normal, b[i].normal) || !same(a[i].albedo, b[i].albedo) || a[i].bounces != b[i].bounces)
      return false;
  return true;
}

TEST(PhotonTracer, IdenticalMapsAtAnyThreadCount) {
  const Scene scene = glassScene(0.6f);
  const Hbvh accel(scene);
  const PhotonSettings s = photonSettings(30000, 30000, 16, 7);
  PhotonMaps one, two;
  {
    ThreadLimit limit(1);
    one = tracePhotons(scene, accel, s);
  }
  {
    ThreadLimit limit(2);
    two = tracePhotons(scene, accel, s);
  }
  ASSERT_FALSE(one.global.empty());
  ASSERT_FALSE(one.caustic.empty());
  EXPECT_TRUE(samePhotons(one.global, two.global));
  EXPECT_TRUE(samePhotons(one.caustic, two.caustic));
  // Another seed gives another map.
  const PhotonMaps other = tracePhotons(scene, accel, photonSettings(30000, 30000, 16, 8));
  EXPECT_FALSE(samePhotons(one.global, other.global));
}

TEST(PhotonTracer, NoLightsGiveEmptyMaps) {
  // The loader refuses a scene without lights; remove them afterwards. A black point light is
  // no light either.
  Scene scene = test::furnaceScene(0.5f, 0.0f, 1.0f, 2);
  scene.pointLights.clear();
  scene.finalize();
  Scene black = test::furnaceScene(0.5f, 0.0f, 1.0f, 2);
  black.pointLights[0].intensity = Vec3(0.0f);
  black.finalize();
  for (const Scene* s : {&scene, &black}) {
    const Hbvh accel(*s);
    const PhotonMaps maps = tracePhotons(*s, accel, photonSettings(1000, 1000));
    EXPECT_TRUE(maps.global.empty());
    EXPECT_TRUE(maps.caustic.empty());
    EXPECT_EQ(maps.stats.emittedGlobal, 0u);
    EXPECT_EQ(maps.stats.emittedPower.x, 0.0f);
  }
}

TEST(PhotonTracer, PhotonsAreValidInCornellBox) {
  const Scene scene = loadScene(test::sourceDir() + "/data/scenes/cornell-box.json");
  const Hbvh accel(scene);
  const PhotonMaps maps = tracePhotons(scene, accel, photonSettings(50000, 0));
  Bounds3 box = scene.bounds();
  for (const Photon& p : maps.global) {
    ASSERT_TRUE(isFinite(p.power) && isFinite(p.position));
    ASSERT_GT(maxComponent(p.power), 0.0f);
    ASSERT_GE(std::min(p.power.x, std::min(p.power.y, p.power.z)), 0.0f);
    ASSERT_NEAR(glm::length(p.incident), 1.0f, 1e-5f);
    ASSERT_NEAR(glm::length(p.normal), 1.0f, 1e-5f);
    ASSERT_GE(glm::dot(p.normal, p.incident), 0.0f);
    for (int a = 0; a < 3; ++a) {
      ASSERT_GE(p.position[a], box.lo[a] - 1e-3f);
      ASSERT_LE(p.position[a], box.hi[a] + 1e-3f);
    }
  }
  // Closed box, all diffuse: the first landings alone carry the whole flux, interreflection
  // adds more.
  const DVec3 sum = totalPower(maps.global);
  for (int c = 0; c < 3; ++c) EXPECT_GT(sum[c], maps.stats.emittedPower[c]);
}

struct CountingProgress : Progress {
  std::string stage;
  uint64_t total = 0;
  std::atomic<uint64_t> done{0};
  bool finished = false;
  uint64_t cancelAfter = ~0ull;
  void start(const std::string& s, uint64_t t) override {
    stage = s;
    total = t;
  }
  void advance(uint64_t u) override { done += u; }
  void finish() override { finished = true; }
  bool cancelled() const override { return done.load() >= cancelAfter; }
};

TEST(PhotonTracer, ProgressAndCancel) {
  const Scene scene = test::furnaceScene(0.5f, 0.0f, 1.0f, 2);
  const Hbvh accel(scene);
  {
    CountingProgress prog;
    const PhotonMaps maps = tracePhotons(scene, accel, photonSettings(10000, 5000), &prog);
    EXPECT_EQ(prog.stage, "photons");
    EXPECT_EQ(prog.total, 15000u);
    EXPECT_EQ(prog.done.load(), 15000u);
    EXPECT_TRUE(prog.finished);
    const nlohmann::json j = maps.stats.toJson();
    EXPECT_EQ(j.at("emitted_global").get<uint64_t>(), 10000u);
    EXPECT_EQ(j.at("emitted_caustic").get<uint64_t>(), 5000u);
    EXPECT_EQ(j.at("stored_global").get<uint64_t>(), maps.global.size());
    EXPECT_EQ(j.at("stored_caustic").get<uint64_t>(), 0u);
    EXPECT_NEAR(j.at("emitted_power")[1].get<double>(), 4.0 * kPi, 1e-4);
    EXPECT_GE(j.at("seconds").get<double>(), 0.0);
  }
  {
    CountingProgress prog;
    prog.cancelAfter = 0;
    EXPECT_THROW(tracePhotons(scene, accel, photonSettings(100000, 0), &prog), CancelledError);
  }
}

}  // namespace
}  // namespace voxcone

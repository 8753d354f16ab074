// The voxcone method: cone weights, furnace spheres, the thin-wall leak and its mitigation,
// agreement with path tracing, determinism across thread counts, option errors.

#include "voxcone/accel/hbvh.h"
#include "voxcone/core/error.h"
#include "voxcone/core/rng.h"
#include "voxcone/image/metrics.h"
#include "voxcone/integrator/voxel_cone/cone_set.h"
#include "voxcone/integrator/voxel_cone/cone_tracer.h"
#include "voxcone/integrator/integrator.h"
#include "voxcone/scene/bsdf.h"

#include "../../support/render_helpers.h"
#include "../../support/report.h"
#include "../../support/test_scenes.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstdio>
#include <fstream>

namespace voxcone {
namespace {

using test::renderWith;

using test::cornellBox;

using test::imageMean;

TEST(ConeSet, WeightsAreTheCosineMeasureOfEachCell) {
  for (int n : {1, 6, 16, 64}) {
    const ConeSet set(n, 0.0f);
    ASSERT_EQ(set.cones().size(), size_t(n));
    EXPECT_NEAR(set.halfAngle(), std::acos(1.0f - 1.0f / n), 1e-6f);
    double sum = 0.0;
    for (const Cone& c : set.cones()) {
      EXPECT_NEAR(glm::length(c.axis), 1.0f, 1e-5f);
      EXPECT_GT(c.axis.z, 0.0f);
      EXPECT_GT(c.weight, 0.0f);
      sum += c.weight;
    }
    EXPECT_NEAR(sum, 1.0, 1e-6) << n;
  }
  // One cone holds the whole hemisphere; with 6 the near-vertical cone weighs most (cos-weighted).
  EXPECT_FLOAT_EQ(ConeSet(1, 0.0f).cones()[0].weight, 1.0f);
  const ConeSet six(6, 0.0f);
  EXPECT_GT(six.cones().front().weight, six.cones().back().weight);
  // Six cones: acos(5/6) = 33.557 degrees by hand.
  EXPECT_NEAR(six.halfAngle() * 180.0f / kPi, 33.557f, 1e-2f);
  EXPECT_THROW(ConeSet(0, 0.0f), SettingsError);
  EXPECT_THROW(ConeSet(6, 2.0f), SettingsError);
}

TEST(ConeTracer, CrossSectionVarianceIsTheCapsByQuadrature) {
  // Per-axis variance of tan(alpha) for directions uniform over the cap alpha <= theta: the
  // mean of tan^2 alpha over the cap's solid angle (weight sin alpha), halved, by the midpoint
  // rule; narrow cones tend to the disc's tan^2(theta) / 4.
  for (double thetaDeg : {0.5, 5.0, 20.4, 33.557, 60.0, 80.0}) {
    const double theta = thetaDeg * kPi / 180.0;
    constexpr int kSteps = 200000;
    double num = 0.0, den = 0.0;
    for (int i = 0; i < kSteps; ++i) {
      const double a = (i + 0.5) / kSteps * theta, t = std::tan(a);
      num += t * t * std::sin(a);
      den += std::sin(a);
    }
    const double expected = 0.5 * num / den;
    EXPECT_NEAR(ConeTracer::crossSectionVariance(float(std::tan(theta))), expected, 1e-5 * expected + 1e-12) << thetaDeg;
  }
  const float narrow = 1e-3f;
  EXPECT_NEAR(ConeTracer::crossSectionVariance(narrow), narrow * narrow / 4.0f, 1e-3f * narrow * narrow);
}

TEST(VoxelCone, EmissiveFurnaceGivesTwo) {
  // Albedo 0.5, Le = 1: L = 2 = emission (1) + direct light by shadow rays (0.5) + cones
  // gathering the walls' reflected radiance 1 (photons, all bounces) times albedo 0.5. Every
  // wall is a lamp, so near_light would leave all of it to the photons at the gathering points
  // (NearLight.AFurnaceOfLampsGivesTwoFromThePhotonsAlone): 0 keeps the cones' own.
  const Scene scene = test::furnaceScene(0.5f, 1.0f, 0.0f, 4, 2);
  // Both mip filters: their weights are normalized (a parent's sum to one), so a closed
  // uniformly lit enclosure stays uniform at every level and every cone sees radiance 1.
  for (const char* filter : {"box", "gaussian"})
    for (const char* gather : {"march", "hit"})
      for (int level : {5, 6}) {
        const RenderResult r = renderWith(scene, "voxcone", scene.render,
                                          {{"photons", 100000},
                                           {"level", level},
                                           {"gather", gather},
                                           {"mip_filter", filter},
                                           {"near_light", 0}});
        const Vec3 m = imageMean(r.image);
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(m[c], 2.0, 0.04) << filter << " " << gather << " level " << level;
        EXPECT_EQ(r.invalidSamples, 0u);
      }
}

/// A closed 4 x 4 x 1 m room, black but for its white floor, whose ceiling has a slot open to a
/// constant sky of radiance 1 across x in [-2, 2], z in [z0, z1]; the camera sees a small patch
/// of floor around the origin.
Scene slotRoom(float z0, float z1) {
  const std::string slot = R"({"type": "quad", "material": "black", "vertices": [[-2, 1, -2], [2, 1, -2], [2, 1, Z], [-2, 1, Z]]},
      {"type": "quad", "material": "black", "vertices": [[-2, 1, W], [2, 1, W], [2, 1, 2], [-2, 1, 2]]})";
  std::string ceiling = slot;
  ceiling.replace(ceiling.find('Z'), 1, std::to_string(z0));
  ceiling.replace(ceiling.find('Z'), 1, std::to_string(z0));
  ceiling.replace(ceiling.find('W'), 1, std::to_string(z1));
  ceiling.replace(ceiling.find('W'), 1, std::to_string(z1));
  const std::string json = R"({
    "camera": {"position": [0, 0.5, 0], "target": [0, 0, 0], "up": [0, 0, 1], "fov_y_deg": 0.5},
    "render": {"width": 4, "height": 4, "spp": 1024, "max_depth": 4},
    "materials": {"white": {"type": "lambertian", "albedo": 1}, "black": {"type": "lambertian", "albedo": 0}},
    "shapes": [
      {"type": "quad", "material": "white", "vertices": [[-2, 0, -2], [-2, 0, 2], [2, 0, 2], [2, 0, -2]]},
      {"type": "quad", "material": "black", "vertices": [[-2, 0, -2], [-2, 1, -2], [-2, 1, 2], [-2, 0, 2]]},
      {"type": "quad", "material": "black", "vertices": [[2, 0, -2], [2, 0, 2], [2, 1, 2], [2, 1, -2]]},
      {"type": "quad", "material": "black", "vertices": [[-2, 0, -2], [2, 0, -2], [2, 1, -2], [-2, 1, -2]]},
      {"type": "quad", "material": "black", "vertices": [[-2, 0, 2], [-2, 1, 2], [2, 1, 2], [2, 0, 2]]},
      )" + ceiling + R"(
    ],
    "lights": [{"type": "environment", "radiance": [1, 1, 1]}]
  })";
  return parseScene(json, "slot", ".");
}

TEST(VoxelCone, SkyThroughASlotMatchesLambertsFormula) {
  // The floor's radiance is the sky's irradiance through the slot over pi (the sky comes by the
  // gather's cones, every sample gathering, no filter): a 5 cm slot 1 m up, its near edge at
  // 45 degrees, 2 degrees of elevation wide straight ahead. Measured with 32 cones (1024 spp,
  // about 4000 axes through the slot, 1.6% of noise): the stratified cosine set 1.016 and 0.992 of
  // Lambert's formula; the cone set turned about the normal alone, at its fixed elevations, 0.996
  // and 0.928.
  for (const auto& [z0, z1] : {std::pair{1.0f, 1.05f}, std::pair{0.95f, 1.0f}}) {
    const Scene scene = slotRoom(z0, z1);
    const std::vector<DVec3> polygon = {{-2, 1, z0}, {2, 1, z0}, {2, 1, z1}, {-2, 1, z1}};
    const double exact = test::lambertPolygonIrradiance(DVec3(0.0), DVec3(0, 1, 0), polygon) / kPi;
    const RenderResult r = renderWith(scene, "voxcone", scene.render,
                                      {{"gathers", 0}, {"filter", 0}, {"gather_spacing", 1}, {"photons", 1000}});
    const double got = double(imageMean(r.image).x);
    std::printf("slot %.2f-%.2f: %.5f, exact %.5f, ratio %.3f\n", z0, z1, got, exact, got / exact);
    EXPECT_NEAR(got / exact, 1.0, 0.05) << "slot at z " << z0 << "-" << z1;
  }
}

TEST(VoxelCone, PointLightFurnaceGivesOne) {
  // Kd = 0.5, I = pi at the centre of a unit sphere: direct 0.5 + indirect 0.5.
  const Scene scene = test::furnaceScene(0.5f, 0.0f, kPi, 4, 2);
  for (int cones : {6, 16}) {
    const Vec3 m = imageMean(renderWith(scene, "voxcone", scene.render, {{"photons", 100000}, {"level", 5}, {"cones", cones}}).image);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(m[c], 1.0, 0.02) << cones << " cones";
  }
}

/// The thin-wall scene: two rooms split by a wall 0.01 thick (a level-5 voxel is 0.0625), the
/// point light in the left room, the front open to nothing, so the right room's true radiance
/// is exactly 0. The camera sees the right room (x > 1) in the left half of the image and the
/// wall edge-on at its centre. `s`: 32x16 at 4 spp.
Scene thinWall(RenderSettings& s) {
  Scene scene = loadScene(test::sourceDir() + "/data/scenes/thin-wall.json");
  s = scene.render;
  s.width = 32;
  s.height = 16;
  s.spp = 4;
  return scene;
}

TEST(VoxelCone, ThinWallLeakIsMeasuredAndExactSegmentsCutIt) {
  RenderSettings s;
  const Scene scene = thinWall(s);
  const Image path = renderWith(scene, "path", s).image;
  EXPECT_EQ(imageMean(path, 0, 15).x, 0.0f);  // no light path reaches the right room
  // The marched cones reading the field's voxels: the field's own leak, and the exact segment
  // that cuts it.
  auto leak = [&](double segment) {
    // Cones on every sample, no filter: the cones' own leak.
    const Image img = renderWith(scene, "voxcone", s,
                                 {{"gather", "march"}, {"hit_radiance", "field"}, {"level", 5}, {"photons", 50000},
                                  {"exact_segment", segment}, {"gathers", 0}, {"filter", 0}})
                          .image;
    return imageMean(img, 0, 15).x / imageMean(img, 17, 32).x;
  };
  const float before = leak(0.0), after = leak(64.0);
  auto hitLeak = [&](const char* hitRadiance) {
    const Image hit = renderWith(scene, "voxcone", s,
                                 {{"level", 5}, {"photons", 50000}, {"cones", 6}, {"hit_radiance", hitRadiance}})
                          .image;
    return imageMean(hit, 0, 15).x / imageMean(hit, 17, 32).x;
  };
  // gather = "hit" reading the field at its hits filters the radiance there over the cone's
  // width, and that lookup reaches through the wall: it leaks as much as no mitigation
  // (measured 1.04% at level 5, 0.95% at level 6, 64x32 at 16 spp). This shows the failure.
  EXPECT_GT(hitLeak("field"), 0.005f);
  // The default, the photons on the hit's own surface and side in sight of it: none.
  EXPECT_EQ(hitLeak("photons"), 0.0f);
  // Measured (64x32, 16 spp): 1.04% before, 0.34% after at level 5 (here, 32x16 at 4 spp:
  // 1.00% and 0.30%). Each voxel keeps the two sides of the wall apart; what is left
  // comes from coarse voxels that mix both rooms' walls.
  EXPECT_GT(before, 0.005f);
  EXPECT_LT(after, 0.5f * before);
  EXPECT_LT(after, 0.005f);
}

TEST(VoxelCone, TheFilterAndItsBorrowingPixelsDoNotCarryLightThroughAThinWall) {
  // The thin wall seen edge-on at the image's centre: the pixels beside it see the floor of
  // both rooms (and the wall's edge), so they are edge pixels that take their samples' light from
  // filter pixels nearby (renderImage), and the filter's rows cross the wall. Through exact
  // links neither reaches the lit room: the dark room's columns, and the column next to the
  // wall alone, stay about as dark as without the filter.
  RenderSettings s;
  const Scene scene = thinWall(s);
  // Path: exactly 0 in columns 0-15. Measured without the filter: the dark room 0.5% of the lit
  // one, column 15 (the wall's dark side) 3.5%; with filter 8 and one gathering pixel per 4x4
  // block: 0.5% and 1.2%. With the links' rays left out (every pair linked): 13% and 50%.
  const nlohmann::json base = {{"level", 5}, {"photons", 50000}, {"exact_segment", 64}, {"filter", 0}};
  nlohmann::json filtered = base;
  filtered.update({{"filter", 8}, {"gather_spacing", 4}});
  for (const nlohmann::json& options : {base, filtered}) {
    const Image img = renderWith(scene, "voxcone", s, options).image;
    const float lit = imageMean(img, 17, 32).x;
    EXPECT_LT(imageMean(img, 0, 15).x / lit, 0.01f) << options.dump();
    EXPECT_LT(imageMean(img, 15, 16).x / lit, 0.05f) << options.dump();
  }
}

TEST(VoxelCone, CornellBoxMeanMatchesPath) {
  // Measured +1.5%, +2.5%, +1.3% (r, g, b) at this size and level (-0.8%, +0.2%, -0.8% at
  // 256x256, level 7); this bounds it at 5%. Before the voxels kept the two sides of each
  // surface apart and the march followed the cone's own axis it was +6.3%, +6.9%, +4.9%.
  const test::CornellMeans m = test::cornellBoxMeans("voxcone", {{"photons", 100000}, {"level", 6}});
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(m.method[c], m.path[c], 0.05 * m.path[c]) << "channel " << c;
}

/// cornell-box with a glass ball (radius 90, index 1.5) in place of the short block: its
/// caustic on the floor and everything seen through it.
Scene cornellGlassBall() {
  std::ifstream f(test::sourceDir() + "/data/scenes/cornell-box.json");
  nlohmann::json j = nlohmann::json::parse(f);
  nlohmann::json shapes = nlohmann::json::array();
  for (const nlohmann::json& shape : j["shapes"])
    if (shape.value("name", "").rfind("short_block", 0) != 0) shapes.push_back(shape);
  shapes.push_back({{"type", "sphere"}, {"name", "ball"}, {"center", {185, 95, 170}}, {"radius", 90},
                    {"subdivisions", 4}, {"material", "glass"}});
  j["shapes"] = shapes;
  j["materials"]["glass"] = {{"type", "dielectric"}, {"ior", 1.5}};
  return parseScene(j.dump(), "cornell-glass-ball", test::sourceDir() + "/data/scenes");
}

/// voxcone's defaults against converged path (1024 spp) on `scene` at 64x64, cell by cell of a
/// 4 x 4 grid: each cell's luminance ratio voxcone / path, row-major from the top.
std::vector<double> regionRatiosAgainstPath(const Scene& scene) {
  RenderSettings s = scene.render;
  s.width = s.height = 64;
  s.spp = 1024;
  const Image path = renderWith(scene, "path", s).image;
  s.spp = 64;
  // The defaults but 16 gathers per gathering pixel: about 256 gathers per cell, so that a
  // cell's mean shows the method's bias, not its noise.
  const Image vc = renderWith(scene, "voxcone", s, {{"gathers", 16}}).image;
  const auto lum = [](const DVec3& v) { return 0.2126 * v.x + 0.7152 * v.y + 0.0722 * v.z; };
  std::vector<double> ratios;
  for (const RegionError& c : regionErrors(vc, path, 4)) ratios.push_back(lum(c.meanTest) / lum(c.meanReference));
  return ratios;
}

TEST(VoxelCone, EveryRegionOfCornellBoxMatchesConvergedPathButTheShortBlocksFront) {
  // Measured: every cell within 8% of path (the bottom row's second, the floor by the tall
  // block, -7%; the top-left one +7%) but cell (2, 3), the short block's front: +30%. That face sees no light directly, and what
  // it sees most of is the floor in front of it, which the block shadows; at level 6 the field's
  // floor voxels and the photon footprints there mix that shadow with the lit floor beyond it,
  // and the coarse mips mix it more. With the field's boundary on the walls it was +35% at
  // 256x256 (now +20%). With the photons at the cones' hits (the default since) it is +17% here
  // and +5% at 256x256, where the screen-space filter's 12 pixels cover a quarter of the area.
  const std::vector<double> r = regionRatiosAgainstPath(cornellBox());
  for (size_t i = 0; i < r.size(); ++i) {
    if (i == 14) continue;
    EXPECT_NEAR(r[i], 1.0, 0.1) << "cell " << i % 4 << ", " << i / 4;
  }
  // Bounded, not required: at the scene's own 256x256 every cell is within 10%
  // (test_canonical_scenes.cpp).
  EXPECT_NEAR(r[14], 1.0, 0.25);
}

TEST(VoxelCone, EveryRegionOfAGlassBallSceneMatchesConvergedPath) {
  // cornell-box with a glass ball for the short block: its caustic, its shadow and the room seen
  // through it. Measured: within 8% (the top-left cell +7.7%, the ball's +6.1%, the bottom row
  // -2% to -3%): bounded at 10%. While the glass was a black occluder in the field the bottom
  // row (the floor around the ball and in its shadow, lit through it) was -4% to -11%; with
  // cones continued through it exactly but its voxels still occluding, -3% to -7%.
  const std::vector<double> r = regionRatiosAgainstPath(cornellGlassBall());
  for (size_t i = 0; i < r.size(); ++i) EXPECT_NEAR(r[i], 1.0, 0.1) << "cell " << i % 4 << ", " << i / 4;
}

/// A lit floor (4 x 4, albedo 0.8) and a square occluder (1 x 1, albedo 0.8) 0.5 above its
/// centre, under a point light 2 above the floor: the occluder's shadow on the floor
/// (|x|, |z| < 2/3) has no direct light, only what the occluder's underside reflects of the lit
/// floor (two bounces and more).
Scene litPlaneWithOccluder() {
  return parseScene(R"({
    "camera": {"position": [0, 3, -4], "target": [0, 0, 0], "up": [0, 1, 0], "fov_y_deg": 40},
    "render": {"width": 8, "height": 8, "spp": 1, "max_depth": 16},
    "materials": {"white": {"type": "lambertian", "albedo": 0.8}},
    "shapes": [
      {"type": "quad", "material": "white", "vertices": [[-2, 0, -2], [2, 0, -2], [2, 0, 2], [-2, 0, 2]]},
      {"type": "quad", "material": "white",
       "vertices": [[-0.5, 0.5, -0.5], [0.5, 0.5, -0.5], [0.5, 0.5, 0.5], [-0.5, 0.5, 0.5]]}],
    "lights": [{"type": "point", "position": [0, 2, 0], "intensity": 10}]
  })", "lit-plane", ".");
}

/// Mean radiance `method` gives over `samples` rays straight down onto the floor at (x, 0, z),
/// from under the occluder.
Vec3 floorRadiance(const Scene& scene, const std::string& method, const nlohmann::json& options, float x, float z,
                   int samples) {
  const Hbvh accel(scene);
  IntegratorContext ctx{scene, accel, scene.render, options};
  auto integrator = createIntegrator(method, ctx);
  integrator->prepare(nullptr);
  DVec3 sum(0.0);
  Sampler sampler(SamplerKind::Sobol, 7, 0);
  for (int i = 0; i < samples; ++i) {
    sampler.startSample(uint32_t(i));
    sum += DVec3(integrator->li(Ray{Vec3(x, 0.25f, z), Vec3(0.0f, -1.0f, 0.0f)}, sampler));
  }
  return Vec3(sum / double(samples));
}

TEST(VoxelCone, LitPlaneWithOccluderMatchesPathInTheShadow) {
  // In the shadow every bit of light is indirect; path tracing with 200k paths per point is
  // the converged value (its standard error is under 0.5%). The field itself is within 5% of
  // path on the occluder's underside at level 6; the cones add their own error.
  const Scene scene = litPlaneWithOccluder();
  for (const Vec2 at : {Vec2(0.0f, 0.0f), Vec2(0.4f, 0.3f)}) {
    const float ref = floorRadiance(scene, "path", nlohmann::json::object(), at.x, at.y, 200000).x;
    ASSERT_GT(ref, 0.0f);
    auto ratio = [&](nlohmann::json options) {
      options.update({{"photons", 200000}, {"level", 6}});
      const float vc = floorRadiance(scene, "voxcone", options, at.x, at.y, 256).x;
      return vc / ref;
    };
    // The default (32 cones, each an exact ray and the photon estimate at its hit): measured
    // +5.2% / +8.6% at the two points (+5.4% / +6.4% with the cone set turned about the normal).
    EXPECT_NEAR(ratio({}), 1.0f, 0.1f);
    // The earlier default, 6 cones marched through the field's voxels: measured +6.8% / +5.7%
    // (+15.8% / +15.4% before the field had a margin: the plane lay on its boundary). Besides
    // the field's own error, lookups beside the occluder's edge count part of it for axes that
    // just miss it, while axes that just hit it count it whole (the exact segment). It was +33%
    // before the march followed the cone's own axis, and +1000% when the occluder's voxels mixed
    // its lit top into its underside.
    EXPECT_NEAR(ratio({{"gather", "march"}, {"cones", 6}, {"hit_radiance", "field"}}), 1.0f, 0.1f);
    // gather = hit reading the field at its hits: its lookup at the cone's width mixes the
    // underside with the floor, and a cone whose axis misses the occluder counts none of it (one
    // that hits counts all). Measured with 64 cones +7.0% / +8.5%, with 6 -2.7% / -6.1%; with the
    // cone set turned about the normal, whose 6 elevations are fixed, 6 cones had been -9% / -23%
    // (-45% / -54% without the field's margin) and 64 +5.9% / +7.4%.
    EXPECT_NEAR(ratio({{"cones", 64}, {"hit_radiance", "field"}}), 1.0f, 0.1f);
    EXPECT_NEAR(ratio({{"cones", 6}, {"hit_radiance", "field"}}), 1.0f, 0.1f);
  }
}

/// A glass ball (radius 1, index 1.5, centre 1.2 above the floor) under a small area light (0.5
/// x 0.5, 4 above the floor): the floor under the ball lies in its shadow and is lit only
/// through it, by the caustic (light -> glass -> glass -> floor); the lens focuses 3.2 below
/// its centre, so the floor 1.2 below meets a soft disc about 0.6 across.
Scene glassBallCaustic() {
  return parseScene(R"({
    "camera": {"position": [0, 3, -5], "target": [0, 0.5, 0], "up": [0, 1, 0], "fov_y_deg": 40},
    "render": {"width": 8, "height": 8, "spp": 1, "max_depth": 16},
    "materials": {"white": {"type": "lambertian", "albedo": 0.8}, "glass": {"type": "dielectric", "ior": 1.5},
                  "light": {"type": "lambertian", "albedo": 0, "emission": [60, 60, 60]}},
    "shapes": [
      {"type": "quad", "material": "white", "vertices": [[3, 0, -3], [-3, 0, -3], [-3, 0, 3], [3, 0, 3]]},
      {"type": "sphere", "material": "glass", "center": [0, 1.2, 0], "radius": 1, "subdivisions": 5},
      {"type": "quad", "material": "light",
       "vertices": [[0.25, 4, -0.25], [0.25, 4, 0.25], [-0.25, 4, 0.25], [-0.25, 4, -0.25]]}]
  })", "glass-ball-caustic", ".");
}

TEST(VoxelCone, AGlassBallsCausticMatchesPath) {
  // Floor points under the ball, seen from just below it (the ball's lowest point is 0.2 up):
  // path tracing finds the caustic by BSDF sampling through the glass onto the light (200k
  // paths per point); voxcone takes it from the caustic grid of aimed caustic photons.
  // Measured +2.3%, -12.7%, -6.7% at the three points (the caustic grid's footprint, 0.08
  // across at level 6, softens the disc's bright rim): bounded at 15%.
  const Scene scene = glassBallCaustic();
  for (const Vec2 at : {Vec2(0.0f, 0.0f), Vec2(0.25f, 0.0f), Vec2(0.0f, -0.4f)}) {
    const float ref = floorRadiance(scene, "path", nlohmann::json::object(), at.x, at.y, 200000).x;
    ASSERT_GT(ref, 0.0f);
    const float vc = floorRadiance(scene, "voxcone", {{"caustic_photons", 200000}}, at.x, at.y, 64).x;
    EXPECT_NEAR(vc / ref, 1.0f, 0.15f) << "at " << at.x << ", " << at.y << ": path " << ref;
  }
}

/// voxcone on cornell-box (res x res, `spp`, one seed: the same photons and first samples) with
/// options `a` and with `a` updated by `b`: the means of the image's left and right halves
/// agree per channel within `tolerance`.
void expectHalvesAgree(int res, int spp, const nlohmann::json& a, const nlohmann::json& b, double tolerance) {
  const Scene scene = test::cornellBox();
  RenderSettings s = scene.render;
  s.width = s.height = res;
  s.spp = spp;
  nlohmann::json changed = a;
  changed.update(b);
  const Image first = renderWith(scene, "voxcone", s, a).image;
  const Image second = renderWith(scene, "voxcone", s, changed).image;
  for (int x0 : {0, res / 2}) {
    const Vec3 ma = imageMean(first, x0, x0 + res / 2), mb = imageMean(second, x0, x0 + res / 2);
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(mb[c] / ma[c], 1.0, tolerance) << b.dump() << ": columns from " << x0 << ", channel " << c;
  }
}

TEST(VoxelCone, GatheringOnFewSamplesKeepsTheMeanInEveryRegion) {
  // gathers = 2 of 16 spp (cones weighted 8) against cones on every sample: the same expected
  // image, so the halves' means agree within their noise (bounded at 3%; a missing weight would
  // be -87% of the indirect light, a doubled one +100%).
  expectHalvesAgree(32, 16, {{"level", 5}, {"photons", 20000}, {"gathers", 0}, {"filter", 0}}, {{"gathers", 2}}, 0.03);
}

TEST(VoxelCone, TheIndirectFilterKeepsTheMeanInEveryRegion) {
  // The screen-space filter of the cones' indirect light (radius 3) against none: the halves'
  // means within 2%: it blurs, it does not add or lose light.
  expectHalvesAgree(48, 8, {{"level", 5}, {"photons", 20000}, {"gathers", 2}, {"filter", 0}}, {{"filter", 3}}, 0.02);
}

TEST(VoxelCone, GatheringOnePixelPerBlockKeepsTheMeanInEveryRegion) {
  // gather_spacing 3 (one gathering pixel per 3x3 block, the filter fills the rest) against
  // every pixel gathering, both with the filter of radius 6: the halves' means within 3% (a
  // non-gathering pixel counted as black would lose 8/9 of the indirect light).
  expectHalvesAgree(48, 4, {{"level", 5}, {"photons", 20000}, {"filter", 6}}, {{"gather_spacing", 3}}, 0.03);
}

/// A closed 2 x 2 x 3 m room (Lambertian 0.7) lit by a 0.6 m lamp on its floor facing up, seen
/// from inside along -z: its back wall (z = -1, 2.8 m from the camera) fills rows and columns
/// 13 to 50 of 64, the pixels of its edges with the floor, the ceiling and the side walls (which
/// see both surfaces) rows and columns 12 and 50 (the normal AOV's).
Scene cornerRoom() {
  return parseScene(R"({
    "camera": {"position": [0, 1.0, 1.8], "target": [0, 1.0, -1], "up": [0, 1, 0], "fov_y_deg": 60},
    "render": {"width": 64, "height": 64, "spp": 16, "max_depth": 16},
    "materials": {"wall": {"type": "lambertian", "albedo": 0.7},
                  "lamp": {"type": "lambertian", "albedo": 0, "emission": 8}},
    "shapes": [
      {"type": "quad", "material": "wall", "vertices": [[-1,0,-1],[1,0,-1],[1,0,2],[-1,0,2]]},
      {"type": "quad", "material": "wall", "vertices": [[-1,2,-1],[-1,2,2],[1,2,2],[1,2,-1]]},
      {"type": "quad", "material": "wall", "vertices": [[-1,0,-1],[-1,2,-1],[1,2,-1],[1,0,-1]]},
      {"type": "quad", "material": "wall", "vertices": [[-1,0,2],[1,0,2],[1,2,2],[-1,2,2]]},
      {"type": "quad", "material": "wall", "vertices": [[-1,0,-1],[-1,0,2],[-1,2,2],[-1,2,-1]]},
      {"type": "quad", "material": "wall", "vertices": [[1,0,-1],[1,2,-1],[1,2,2],[1,0,2]]},
      {"type": "quad", "material": "lamp", "vertices": [[-0.3,0.02,0.2],[-0.3,0.02,0.8],[0.3,0.02,0.8],[0.3,0.02,0.2]]}
    ]
  })",
                    "corner-room", ".");
}

TEST(VoxelCone, TheIndirectFilterDoesNotCarryAWallsLightIntoItsEdges) {
  // The back wall's strips along its edge with the floor (rows 46-49) and with the left wall
  // (columns 13-16), against path at 1024 spp: near a concave edge the other surface hides part
  // of the room, and a screen-space filter that averages the wall's middle into the strip makes
  // it too bright. filter_reach 1 (the default) keeps each pixel's light within its distance to
  // the edge; filter_reach 0 is the filter before it. Seeds 1-4 averaged. Measured: the floor
  // strip 1.027 / 1.012 of path (0 / 1), the left strip 1.019 / 1.004 (filter 0, a gather at
  // every pixel: 1.010 and 1.004 against path at 4096 spp).
  const Scene scene = cornerRoom();
  RenderSettings p = scene.render;
  p.spp = 1024;
  p.seed = 99;
  const Image path = renderWith(scene, "path", p).image;
  const auto strip = [](const Image& img, int x0, int x1, int y0, int y1) {
    double sum = 0.0;
    for (int y = y0; y < y1; ++y)
      for (int x = x0; x < x1; ++x) sum += test::luminance(DVec3(img.at(x, y)));
    return sum;
  };
  double floorStrip[2] = {0.0, 0.0}, sideStrip[2] = {0.0, 0.0};
  for (const int reach : {0, 1})
    for (const uint64_t seed : {1u, 2u, 3u, 4u}) {
      RenderSettings s = scene.render;
      s.seed = seed;
      const Image img = renderWith(scene, "voxcone", s, {{"filter_reach", reach}}).image;
      floorStrip[reach] += 0.25 * strip(img, 16, 48, 46, 50) / strip(path, 16, 48, 46, 50);
      sideStrip[reach] += 0.25 * strip(img, 13, 17, 16, 48) / strip(path, 13, 17, 16, 48);
    }
  // The strips' mean excess over path's.
  const double excess[2] = {0.5 * (floorStrip[0] + sideStrip[0]) - 1.0, 0.5 * (floorStrip[1] + sideStrip[1]) - 1.0};
  test::report("floor strip / path's, filter_reach 1 (bound 1 +- 0.025)", floorStrip[1], 1.025);
  test::report("left strip / path's, filter_reach 1 (bound 1 +- 0.015)", sideStrip[1], 1.015);
  test::report("floor strip / path's, filter_reach 0", floorStrip[0]);
  test::report("left strip / path's, filter_reach 0", sideStrip[0]);
  test::report("strips' excess, filter_reach 0 (lower bound reach 1's + 0.01)", excess[0], excess[1] + 0.01);
  EXPECT_NEAR(floorStrip[1], 1.0, 0.025);
  EXPECT_NEAR(sideStrip[1], 1.0, 0.015);
  // Without the reach the strips are brighter (the failure this guards).
  EXPECT_GT(excess[0], excess[1] + 0.01);
}

TEST(VoxelCone, ShadowRaysAtConeHitsKeepTheMeanAndCutThePixelNoise) {
  // The lamp room (its lamp 2 cm under the ceiling, behind the camera: the walls and floor the
  // cones hit are lit by it; near_light 0, so that the cones take all of the light beside the
  // lamp), one photon map (the option seed makes the photon seed 10 at every pixel seed): 4
  // shadow rays at each cone's hit against 1. Both estimate the same light, so the images' means
  // agree within their noise (a cell's is about 0.044, the mean of four images' 0.003), and the
  // 8 x 8 cells move less from pixel seed to pixel seed with 4 (the root mean square of the
  // cells' relative differences over pixel seeds 1 / 2 and 3 / 4, each known to about 6%).
  // Measured: the means 0.9913 apart; the cells 0.0628 apart with 1 ray, 0.0390 with 4 (with the
  // default near_light, which leaves the cones less of the lamp's light: 0.0297 and 0.0256).
  const Scene scene = test::lampUnderCeilingScene(0.02f, 32, 16);
  const auto render = [&](int rays, uint64_t seed) {
    RenderSettings s = scene.render;
    s.seed = seed;
    return renderWith(scene, "voxcone", s, {{"hit_light_samples", rays}, {"seed", 10 - seed}, {"near_light", 0}}).image;
  };
  double meanOne = 0.0, meanFour = 0.0, squaresOne = 0.0, squaresFour = 0.0;
  int cells = 0;
  for (const uint64_t seed : {1u, 3u}) {
    const Image one[2] = {render(1, seed), render(1, seed + 1)}, four[2] = {render(4, seed), render(4, seed + 1)};
    for (int i = 0; i < 2; ++i) {
      meanOne += test::luminance(DVec3(imageMean(one[i])));
      meanFour += test::luminance(DVec3(imageMean(four[i])));
    }
    const std::vector<RegionError> a = regionErrors(one[0], one[1], 8), b = regionErrors(four[0], four[1], 8);
    for (size_t c = 0; c < a.size(); ++c) {
      squaresOne += std::pow(test::luminance(a[c].meanTest) / test::luminance(a[c].meanReference) - 1.0, 2.0);
      squaresFour += std::pow(test::luminance(b[c].meanTest) / test::luminance(b[c].meanReference) - 1.0, 2.0);
      ++cells;
    }
  }
  const double rmsOne = std::sqrt(squaresOne / cells), rmsFour = std::sqrt(squaresFour / cells);
  test::report("mean with 4 rays / with 1 - 1 (bound on |x|)", meanFour / meanOne - 1.0, 0.02);
  test::report("cells apart between pixel seeds (rms), 1 ray", rmsOne);
  test::report("cells apart between pixel seeds (rms), 4 rays (bound 0.8x 1 ray's)", rmsFour, 0.8 * rmsOne);
  EXPECT_NEAR(meanFour / meanOne, 1.0, 0.02);
  EXPECT_LT(rmsFour, 0.8 * rmsOne);
}

TEST(VoxelCone, SameImageAtOneAndTwoThreadsWithOneGatherPerBlock) {
  const Scene scene = cornellBox();
  RenderSettings s = scene.render;
  s.width = s.height = 40;
  s.spp = 2;
  EXPECT_EQ(test::pixelsDifferingAcrossThreads(scene, "voxcone", s,
                                               {{"photons", 20000}, {"level", 5}, {"gather_spacing", 4}, {"filter", 8}}),
            0u);
}

TEST(VoxelCone, SameImageAtOneAndTwoThreads) {
  const Scene scene = cornellBox();
  RenderSettings s = scene.render;
  s.width = s.height = 40;  // not a multiple of the tile size
  s.spp = 2;
EXPECT_EQ(test::pixelsDifferingAcrossThreads(scene, "voxcone", s, {{"photons", 50000}, {"level", 6}}), 0u);
}

/// A light seen only in a mirror: the camera at the origin looks along +z at a mirror of
/// reflectance 0.8 at z = 10 that fills its view; the light (radiance 5 on both sides), a square
/// of half-size 6 at z = -10, is behind the camera. Its image in the mirror lies at distance 30,
/// so it covers the square of half-width (6 / 30) / tan 30 deg = 0.34641 of the image's
/// half-width around the centre, and a pixel's exact value is 0.8 * 5 times the share of it the
/// square covers.
struct MirroredLight {
  Scene scene;
  std::vector<float> exact;  // per pixel
};
MirroredLight mirroredLight(int size, int spp) {
  nlohmann::json j = nlohmann::json::parse(R"({
    "camera": {"position": [0, 0, 0], "target": [0, 0, 1], "up": [0, 1, 0], "fov_y_deg": 60},
    "materials": {"mirror": {"type": "mirror", "specular": 0.8},
                  "lamp": {"type": "lambertian", "albedo": 0, "emission": 5, "two_sided_emission": true}},
    "shapes": [{"type": "quad", "material": "mirror", "vertices": [[-20, -20, 10], [20, -20, 10], [20, 20, 10], [-20, 20, 10]]},
               {"type": "quad", "material": "lamp", "vertices": [[-6, -6, -10], [6, -6, -10], [6, 6, -10], [-6, 6, -10]]}]
  })");
  j["render"] = {{"width", size}, {"height", size}, {"spp", spp}};
  MirroredLight m{parseScene(j.dump(), "mirrored-light", "."), {}};
  const double half = 0.5 * size, lo = half * (1.0 - 0.2 / std::tan(kPi / 6.0)), hi = 2.0 * half - lo;
  const auto overlap = [&](int i) { return std::max(0.0, std::min(double(i + 1), hi) - std::max(double(i), lo)); };
  for (int y = 0; y < size; ++y)
    for (int x = 0; x < size; ++x) m.exact.push_back(float(4.0 * overlap(x) * overlap(y)));
  return m;
}

TEST(VoxelCone, GlintSamplesSeeALightInAMirrorAsItIsWithLessNoise) {
  // Without glint samples and with 16 per camera sample, every pixel is its exact value in
  // expectation (the pixels wholly inside or outside the light's image exactly), the image's
  // mean within 1% of the exact 4 * 0.34641^2 = 0.48; the glint samples cut the error of the
  // pixels on the image's edges (64 samples each instead of 4: to below half).
  const MirroredLight m = mirroredLight(32, 4);
  double rms[2];
  for (int k : {0, 16}) {
    const Image img = renderWith(m.scene, "voxcone", m.scene.render, {{"photons", 1000}, {"glint_samples", k}}).image;
    double sum = 0.0, sq = 0.0;
    for (size_t p = 0; p < img.pixels.size(); ++p) {
      const float e = m.exact[p];
      if (e == 0.0f || e == 4.0f) {
        EXPECT_NEAR(img.pixels[p].y, e, 1e-5f) << "glints " << k << ", pixel " << p;
      }
      sum += img.pixels[p].y;
      sq += (img.pixels[p].y - e) * (img.pixels[p].y - e);
      EXPECT_EQ(img.pixels[p].x, img.pixels[p].y);
    }
    EXPECT_NEAR(sum / double(img.pixels.size()), 0.48, 0.0048) << "glints " << k;
    rms[k > 0] = std::sqrt(sq / double(img.pixels.size()));
  }
  EXPECT_GT(rms[0], 0.0);
  EXPECT_LT(rms[1], 0.5 * rms[0]) << "without " << rms[0] << ", with " << rms[1];
}

TEST(VoxelCone, GlintSamplesSameImageAtOneAndTwoThreadsWithTheFilterAndWithout) {
  const MirroredLight m = mirroredLight(20, 2);
  for (int filter : {12, 0})
    EXPECT_EQ(test::pixelsDifferingAcrossThreads(m.scene, "voxcone", m.scene.render,
                                                 {{"photons", 1000}, {"glint_samples", 4}, {"filter", filter}}),
              0u)
        << filter;
}

TEST(VoxelCone, GlintSamplesChangeNothingWithoutMirrorsOrGlass) {
  const Scene scene = cornellBox();
  RenderSettings s = scene.render;
  s.width = s.height = 24;
  s.spp = 2;
  const nlohmann::json options = {{"photons", 20000}};
  nlohmann::json glints = options;
  glints["glint_samples"] = 8;
  EXPECT_EQ(renderWith(scene, "voxcone", s, options).image.pixels, renderWith(scene, "voxcone", s, glints).image.pixels);
}

TEST(VoxelCone, ARoughMetalBlockPassesItsLightOnInEveryRegion) {
  // cornell-box with the tall block rough gold (roughness 0.2): the walls beside it take light
  // it reflects, and the block shows the room. A cone whose exact ray met the block once took
  // nothing there (no photon estimate on a glossy surface), and the block's own glossy cone ran
  // on one sample per pixel: the rough gold dragon was 8% dark, relMSE 0.012 where path needs
  // 10 spp for it. At 64x64 the cells were 0.72-1.10 of path at 256 spp, their mean 0.930; now
  // 0.93-1.11 (the 1.11 cell, the floor before the short block, the same before), mean 1.002.
  // Bounds: the canonical scenes' 13% per cell, 3% on the cells' mean, on the mean image of two
  // seeds: that cell alone moves by up to 17% from seed to seed (against path at 4096 spp, four
  // seeds: 0.98-1.16 with the gather's stratified cosine set, 1.03-1.10 with the cone set turned
  // about the normal, whose seed 1 put another cell at 1.23).
  std::ifstream f(test::sourceDir() + "/data/scenes/cornell-box.json");
  nlohmann::json j = nlohmann::json::parse(f);
  j["materials"]["gold_rough"] = {{"type", "rough_conductor"}, {"eta", {0.143, 0.374, 1.442}},
                                  {"k", {3.983, 2.385, 1.603}}, {"roughness", 0.2}};
  for (auto& shape : j["shapes"])
    if (shape.value("name", "").rfind("tall_block", 0) == 0) shape["material"] = "gold_rough";
  j["render"]["width"] = j["render"]["height"] = 64;
  j["render"]["spp"] = 16;
  const Scene scene = parseScene(j.dump(), "cornell-rough-gold", test::sourceDir() + "/data/scenes");
  RenderSettings p = scene.render;
  p.spp = 256;
  p.seed = 1234;
  const Image path = renderWith(scene, "path", p).image;
  Image vc = renderWith(scene, "voxcone", scene.render).image;
  RenderSettings second = scene.render;
  second.seed = scene.render.seed + 1;
  const Image other = renderWith(scene, "voxcone", second).image;
  for (size_t i = 0; i < vc.pixels.size(); ++i) vc.pixels[i] = 0.5f * (vc.pixels[i] + other.pixels[i]);
  std::vector<double> r;
  for (const RegionError& c : regionErrors(vc, path, 4)) r.push_back(test::luminance(c.meanTest) / test::luminance(c.meanReference));
  double mean = 0.0;
  for (size_t i = 0; i < r.size(); ++i) {
    EXPECT_NEAR(r[i], 1.0, 0.13) << "cell " << i % 4 << ", " << i / 4;
    mean += r[i] / double(r.size());
  }
  EXPECT_NEAR(mean, 1.0, 0.03);
}

/// Directional albedo of `m` at local wo: the integral of f cos over the sphere of wi, by the
/// midpoint rule in (cos theta, phi) (cos theta from -1: a dielectric's transmission too).
double directionalAlbedo(const Material& m, const Vec3& wo) {
  constexpr int kTheta = 1600, kPhi = 400;
  double sum = 0.0;
  for (int i = 0; i < kTheta; ++i) {
    const double c = -1.0 + 2.0 * (i + 0.5) / kTheta, sinT = std::sqrt(std::max(0.0, 1.0 - c * c));
    for (int j = 0; j < kPhi; ++j) {
      const double phi = 2.0 * kPi * (j + 0.5) / kPhi;
      const Vec3 wi(float(sinT * std::cos(phi)), float(sinT * std::sin(phi)), float(c));
      sum += double(luminance(bsdfEval(m, wo, wi))) * std::fabs(c);
    }
  }
  return sum * (2.0 / kTheta) * (2.0 * kPi / kPhi);
}

TEST(VoxelCone, ARoughConductorInAFurnaceReflectsItsAlbedoIntegral) {
  // A 0.2 x 0.2 rough-aluminium plate at the centre of a closed sphere of radius 1 whose wall
  // (albedo 0.5) emits 1 on both sides: the wall's radiance is 1 / (1 - 0.5) = 2 (the plate,
  // 0.3% of the wall's area, changes it by less than that), so the plate reflects 2 A(wo), A
  // its directional albedo, half of it from the lights by shadow rays and half through the
  // glossy cones (the photons' bounced light on the wall plus the light at each cone's hit). A
  // narrow camera at 40 degrees from the plate's normal: every pixel sees it at nearly one wo.
  // Roughness 0.05 (one ray), 0.25 and 0.6 (4 cones each). Bound: 2% of 2 A, against A by
  // quadrature of the BSDF; path the same within 2%, as a check of the set-up. Measured at 16
  // spp: voxcone 0.13%, 0.2%, 0.65% low, path 0.3%, 0.4%, 1.0% high; before the cones'
  // emission was MIS-weighted against the light samples, roughness 0.05 was 3.3% low.
  for (double roughness : {0.05, 0.25, 0.6}) {
    const double theta = 40.0 * kPi / 180.0;
    const Vec3 eye(float(0.5 * std::sin(theta)), 0.0f, float(0.5 * std::cos(theta)));
    nlohmann::json j;
    j["camera"] = {{"position", {eye.x, eye.y, eye.z}}, {"target", {0, 0, 0}}, {"up", {0, 1, 0}}, {"fov_y_deg", 8}};
    j["render"] = {{"width", 16}, {"height", 16}, {"spp", 16}, {"max_depth", 64}};
    j["materials"]["wall"] = {{"type", "lambertian"}, {"albedo", 0.5}, {"emission", 1.0}, {"two_sided_emission", true}};
    j["materials"]["metal"] = {{"type", "rough_conductor"}, {"eta", {1.657, 0.880, 0.521}},
                               {"k", {9.224, 6.270, 4.837}}, {"roughness", roughness}};
    j["shapes"].push_back({{"type", "sphere"}, {"center", {0, 0, 0}}, {"radius", 1}, {"subdivisions", 4}, {"material", "wall"}});
    j["shapes"].push_back({{"type", "quad"}, {"material", "metal"},
                           {"vertices", {{-0.1, -0.1, 0}, {0.1, -0.1, 0}, {0.1, 0.1, 0}, {-0.1, 0.1, 0}}}});
    const Scene scene = parseScene(j.dump(), "conductor-furnace", ".");
    Material metal;
    for (const Material& m : scene.materials)
      if (m.type == MaterialType::RoughConductor) metal = m;
    const double expected = 2.0 * directionalAlbedo(metal, Vec3(float(std::sin(theta)), 0.0f, float(std::cos(theta))));
    for (const char* method : {"voxcone", "path"}) {
      const Vec3 m = imageMean(renderWith(scene, method, scene.render, nlohmann::json::object()).image);
      const double lum = luminance(m);
      std::printf("roughness %.2f %s: %.4f, 2 A(wo) = %.4f\n", roughness, method, lum, expected);
      EXPECT_NEAR(lum / expected, 1.0, 0.02) << method << " roughness " << roughness;
    }
  }
}

TEST(VoxelCone, ARoughConductorUnderAConstantSkyReflectsItsAlbedoIntegral) {
  // The plate of the furnace above alone under a constant sky of radiance 1: it reflects A(wo),
  // all of it direct light, part found by the light samples (the sky's own sampler: under MIS
  // their density must be the one the cones' weights assume) and part by the glossy cones that
  // leave the scene. Bound 2% (16x16 at 16 spp). Measured: voxcone within 0.02%, path 0.15%;
  // with the light samples drawn from the sky's cosine mixture while the cones' weights assumed
  // its own sampler, voxcone was 2.7% and 4.4% bright.
  for (double roughness : {0.05, 0.25}) {
    const double theta = 40.0 * kPi / 180.0;
    const Vec3 eye(float(0.5 * std::sin(theta)), 0.0f, float(0.5 * std::cos(theta)));
    nlohmann::json j;
    j["camera"] = {{"position", {eye.x, eye.y, eye.z}}, {"target", {0, 0, 0}}, {"up", {0, 1, 0}}, {"fov_y_deg", 8}};
    j["render"] = {{"width", 16}, {"height", 16}, {"spp", 16}};
    j["materials"]["metal"] = {{"type", "rough_conductor"}, {"eta", {1.657, 0.880, 0.521}},
                               {"k", {9.224, 6.270, 4.837}}, {"roughness", roughness}};
    j["shapes"].push_back({{"type", "quad"}, {"material", "metal"},
                           {"vertices", {{-0.1, -0.1, 0}, {0.1, -0.1, 0}, {0.1, 0.1, 0}, {-0.1, 0.1, 0}}}});
    j["lights"].push_back({{"type", "environment"}, {"radiance", {1, 1, 1}}});
    const Scene scene = parseScene(j.dump(), "conductor-sky", ".");
    const double expected =
        directionalAlbedo(scene.materials[0], Vec3(float(std::sin(theta)), 0.0f, float(std::cos(theta))));
    for (const char* method : {"voxcone", "path"}) {
      const double lum = luminance(imageMean(renderWith(scene, method, scene.render, nlohmann::json::object()).image));
      std::printf("sky, roughness %.2f %s: %.4f, A(wo) = %.4f\n", roughness, method, lum, expected);
      EXPECT_NEAR(lum / expected, 1.0, 0.02) << method << " roughness " << roughness;
    }
  }
}

TEST(VoxelCone, BadOptionsAreSettingsErrors) {
  const Scene scene = test::furnaceScene(0.5f, 1.0f, 0.0f, 2, 1);
  const Hbvh accel(scene);
  for (const char* bad : {R"({"cones": 0})", R"({"level": 13})", R"({"view": "nope"})", R"({"unknown": 1})",
                          R"({"cone_angle": -1})", R"({"coarsest_level": 9, "level": 8})",
                          R"({"gather_spacing": 2, "filter": 0})", R"({"gather_spacing": 0})",
                          R"({"photon_guide": -0.1})", R"({"photon_guide": 1.5})", R"({"photon_guide": "yes"})",
                          R"({"glossy_cones": 0})", R"({"glossy_cones": 65})", R"({"glossy_switch": 0})",
                          R"({"distant_aim": -0.1})", R"({"distant_aim": 1})", R"({"hit_sky": "cones"})",
                          R"({"edge_fit": "hit"})", R"({"edge_fit": true})", R"({"lamp_photons": -1})"}) {
    IntegratorContext ctx{scene, accel, scene.render, nlohmann::json::parse(bad)};
    EXPECT_THROW(createIntegrator("voxcone", ctx), SettingsError) << bad;
  }
}

}  // namespace
}  // namespace voxcone

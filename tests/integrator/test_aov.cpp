// AOV layers (--aov): the first-hit layers against a scene whose every value is known, the
// radiance terms adding up to the beauty, each term against a render that computes it alone,
// and the beauty unchanged by asking for layers.

#include "voxcone/accel/hbvh.h"
#include "voxcone/core/error.h"
#include "voxcone/integrator/integrator.h"

#include "../support/render_helpers.h"
#include "../support/test_scenes.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <fstream>

namespace voxcone {
namespace {

/// renderWith, with the layers `layers` (all seven when empty).
RenderResult renderAovs(const Scene& scene, const std::string& method, RenderSettings settings,
                        nlohmann::json options = nlohmann::json::object(), std::vector<Aov> layers = {}) {
  const Hbvh accel(scene);
  settings.method = method;
  IntegratorContext ctx{scene, accel, settings, options};
  auto integrator = createIntegrator(method, ctx);
  integrator->prepare(nullptr);
  AovRequest request;
  request.accel = &accel;
  request.layers = layers;
  if (layers.empty())
    for (size_t i = 0; i < aovNames().size(); ++i) request.layers.push_back(Aov(i));
  return renderImage(scene, *integrator, settings, nullptr, false, &request);
}

const ImageLayer& layer(const RenderResult& r, const std::string& name) {
  for (const ImageLayer& l : r.layers)
    if (l.name == name) return l;
  throw Error("no layer " + name);
}

/// A layer's value at pixel p, channel c.
float at(const ImageLayer& l, size_t p, size_t c) { return l.values[p * l.channels.size() + c]; }

/// cornell-box's settings at `size` x `size` pixels and `spp` samples.
RenderSettings smallSettings(const Scene& scene, int size, int spp) {
  RenderSettings s = scene.render;
  s.width = s.height = size;
  s.spp = spp;
  return s;
}

/// The cornell-box with a glass sphere (IOR 1.5) on the floor: light reaches the floor
/// through it (caustic), the camera sees the light through it (emitted via delta bounces).
Scene cornellWithGlassBall(int width, int spp) {
  std::ifstream f(test::sourceDir() + "/data/scenes/cornell-box.json");
  nlohmann::json j = nlohmann::json::parse(f);
  j["materials"]["glass"] = {{"type", "dielectric"}, {"ior", 1.5}};
  j["shapes"].push_back({{"type", "sphere"}, {"center", {400, 90, 150}}, {"radius", 90}, {"subdivisions", 4},
                         {"material", "glass"}});
  j["render"]["width"] = j["render"]["height"] = width;
  j["render"]["spp"] = spp;
  return parseScene(j.dump(), "cornell-glass-ball", test::sourceDir() + "/data/scenes");
}

TEST(Aov, ParseNamesAndRefuseUnknownOrRepeated) {
  EXPECT_EQ(parseAovs("albedo,depth"), (std::vector<Aov>{Aov::Albedo, Aov::Depth}));
  EXPECT_EQ(aovChannels(Aov::Normal), (std::vector<std::string>{"Ns.X", "Ns.Y", "Ns.Z"}));
  EXPECT_EQ(aovChannels(Aov::Depth), (std::vector<std::string>{"Z"}));
  EXPECT_THROW(parseAovs("albedo,albedo"), SettingsError);
  EXPECT_THROW(parseAovs("beauty"), SettingsError);
  EXPECT_THROW(parseAovs(""), SettingsError);
  EXPECT_THROW(parseAovs("albedo,"), SettingsError);
}

TEST(Aov, FirstHitLayersOfAWallAtAKnownDistance) {
  // A wall z = 10 (normal -z, towards the camera), albedo (0.2, 0.4, 0.6), seen from the
  // origin through a 60 degree lens: every pixel inside the wall's square has Z = 10 exactly
  // (distance along the viewing axis, not along the ray), albedo the material's, Ns (0, 0, -1);
  // pixels past its edge see nothing and hold 0.
  const Scene scene = parseScene(R"({
    "camera": {"position": [0, 0, 0], "target": [0, 0, 1], "up": [0, 1, 0], "fov_y_deg": 60},
    "render": {"width": 16, "height": 16, "spp": 4},
    "materials": {"wall": {"type": "lambertian", "albedo": [0.2, 0.4, 0.6]},
                  "lamp": {"type": "lambertian", "albedo": 0, "emission": 1}},
    "lights": [{"type": "point", "position": [0, 0, 5], "intensity": 10}],
    "shapes": [{"type": "quad", "material": "wall", "vertices": [[-3, -3, 10], [3, -3, 10], [3, 3, 10], [-3, 3, 10]]}]
  })", "wall", ".");
  const RenderResult r = renderAovs(scene, "path", scene.render, nlohmann::json::object(),
                                    {Aov::Albedo, Aov::Normal, Aov::Depth});
  const ImageLayer &albedo = layer(r, "albedo"), &normal = layer(r, "normal"), &depth = layer(r, "depth");
  // tan(30 deg) * 10 = 5.77 > 3: the wall fills the middle 3 / 5.77 of the image, rows and columns
  // 2..13 wholly (pixel edges at 8 +- 8 * 3 / 5.7735 = 3.84 .. 12.16).
  int inside = 0, outside = 0;
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x) {
      const size_t p = size_t(y) * 16 + size_t(x);
      if (x >= 4 && x < 12 && y >= 4 && y < 12) {
        ++inside;
        EXPECT_NEAR(at(depth, p, 0), 10.0f, 1e-4f) << x << "," << y;
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(at(albedo, p, size_t(c)), 0.2f * float(c + 1), 1e-6f);
        EXPECT_NEAR(at(normal, p, 2), -1.0f, 1e-6f);
        EXPECT_NEAR(at(normal, p, 0), 0.0f, 1e-6f);
      } else if (x < 3 || x > 12 || y < 3 || y > 12) {
        ++outside;
        EXPECT_EQ(at(depth, p, 0), 0.0f) << x << "," << y;
        EXPECT_EQ(at(albedo, p, 0), 0.0f);
      }
    }
  EXPECT_EQ(inside, 64);
  EXPECT_GT(outside, 0);
}

/// Per pixel and channel: the terms sum to the beauty within float rounding.
void expectTermsAddUp(const RenderResult& r, const std::string& what) {
  const ImageLayer &e = layer(r, "emitted"), &d = layer(r, "direct"), &i = layer(r, "indirect"),
                   &c = layer(r, "caustic");
  double worst = 0.0;
  for (size_t p = 0; p < r.image.pixels.size(); ++p)
    for (size_t k = 0; k < 3; ++k) {
      const double sum = double(at(e, p, k)) + at(d, p, k) + at(i, p, k) + at(c, p, k);
      const double beauty = r.image.pixels[p][int(k)];
      worst = std::max(worst, std::fabs(sum - beauty) / (1e-3 + std::fabs(beauty)));
    }
  EXPECT_LT(worst, 1e-4) << what << ": the terms do not add up to the beauty";
}

double layerMean(const ImageLayer& l) {
  double s = 0.0;
  for (float v : l.values) s += v;
  return s / double(l.values.size());
}

TEST(Aov, TermsAddUpToTheBeautyAndAskingForThemChangesNothing) {
  const Scene plain = test::cornellBox();
  const Scene glass = cornellWithGlassBall(24, 8);
  const RenderSettings s = smallSettings(plain, 24, 8);
  for (const Scene* scene : {&plain, &glass})
    for (const char* method : {"path", "whitted", "voxcone"}) {
      const std::string what = scene->sourcePath + " " + method;
      const RenderResult with = renderAovs(*scene, method, s);
      const RenderResult without = test::renderWith(*scene, method, s);
      EXPECT_EQ(with.image.pixels, without.image.pixels) << what << ": the layers changed the beauty";
      expectTermsAddUp(with, what);
      EXPECT_GT(layerMean(layer(with, "direct")), 0.0) << what;
      EXPECT_GT(layerMean(layer(with, "emitted")), 0.0) << what;  // the light itself
      if (std::string(method) == "whitted") EXPECT_EQ(layerMean(layer(with, "indirect")), 0.0) << what;
      else EXPECT_GT(layerMean(layer(with, "indirect")), 0.0) << what;
      // Only through glass is there a caustic (path: L S+ D; voxcone: its caustic photons).
      if (scene == &plain || std::string(method) == "whitted") EXPECT_EQ(layerMean(layer(with, "caustic")), 0.0) << what;
      else EXPECT_GT(layerMean(layer(with, "caustic")), 0.0) << what;
    }
}

/// Per pixel and channel: the emitted and direct layers of `full` sum to `image` (a render
/// that computes those two terms alone from the same random numbers).
void expectEmittedPlusDirectIs(const RenderResult& full, const Image& image) {
  const ImageLayer &e = layer(full, "emitted"), &d = layer(full, "direct");
  for (size_t p = 0; p < image.pixels.size(); ++p)
    for (size_t k = 0; k < 3; ++k)
      EXPECT_NEAR(at(e, p, k) + at(d, p, k), image.pixels[p][int(k)], 1e-5f * (1.0f + image.pixels[p][int(k)])) << p;
}

TEST(Aov, PathEmittedPlusDirectIsThePathOfTwoSegments) {
  // In the cornell-box (no delta surface) emitted + direct is every path of at most two
  // segments, E L and E D L: path at max_depth 2 computes exactly that with the same random
  // numbers (roulette starts at depth 3), so the layers must equal its image.
  const Scene scene = test::cornellBox();
  RenderSettings s = smallSettings(scene, 24, 8);
  const RenderResult full = renderAovs(scene, "path", s);
  s.maxDepth = 2;
  const RenderResult two = test::renderWith(scene, "path", s);
  expectEmittedPlusDirectIs(full, two.image);
}

TEST(Aov, VoxconeEmittedPlusDirectIsItsDirectView) {
  // voxcone's view "direct" renders emission and direct light alone, drawing the same random
  // numbers for them: its image is the full render's emitted + direct layers.
  const Scene scene = test::cornellBox();
  RenderSettings s = smallSettings(scene, 24, 8);
  const RenderResult full = renderAovs(scene, "voxcone", s);
  const RenderResult direct = test::renderWith(scene, "voxcone", s, {{"view", "direct"}});
  expectEmittedPlusDirectIs(full, direct.image);
}

TEST(Aov, VoxconesGlintSamplesKeepTheTermsAddingUp) {
  // The glint samples replace the camera samples' glints in the beauty and the emitted layer
  // alike, with the filter and without it.
  const Scene glass = cornellWithGlassBall(24, 4);
  const RenderSettings s = smallSettings(glass, 24, 4);
  for (int filter : {12, 0}) {
    const nlohmann::json options = {{"glint_samples", 4}, {"filter", filter}, {"photons", 20000}};
    const RenderResult with = renderAovs(glass, "voxcone", s, options);
    EXPECT_EQ(with.image.pixels, test::renderWith(glass, "voxcone", s, options).image.pixels) << filter;
    expectTermsAddUp(with, "glints, filter " + std::to_string(filter));
    nlohmann::json none = options;
    none["glint_samples"] = 0;
    EXPECT_NE(with.image.pixels, test::renderWith(glass, "voxcone", s, none).image.pixels) << filter;
  }
}

TEST(Aov, TermLayersNeedAMethodThatSeparatesThem) {
  const Scene scene = test::cornellBox();
  RenderSettings s = smallSettings(scene, 8, 1);
  s.photons = 2000;
  EXPECT_THROW(renderAovs(scene, "pm", s, nlohmann::json::object(), {Aov::Direct}), SettingsError);
  // The first-hit layers need nothing of the integrator.
  EXPECT_EQ(renderAovs(scene, "pm", s, nlohmann::json::object(), {Aov::Albedo}).layers.size(), 1u);
}

}  // namespace
}  // namespace voxcone

// Coated diffuse (plastic, roughplastic) and the thin dielectric in every method, against
// closed forms per block of pixels: a coated plane under a constant white sky reflects F(mu) +
// (1 - F(mu)) albedo with a smooth coat (the base's share reduces to the albedo by the
// reciprocity 1 - Fdr_ext = n^2 (1 - Fdr_int)), and a thin pane in front of a uniform emitter
// passes 1 - 2F / (1 + F). Also the JSON and Mitsuba writers' round trip of the new materials.

#include "voxcone/scene/bsdf.h"
#include "voxcone/scene/mitsuba.h"
#include "voxcone/scene/scene.h"

#include "../support/render_helpers.h"
#include "../support/report.h"
#include "../support/temp_dir.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <string>

namespace voxcone {
namespace {

using test::renderWith;
using test::report;

/// A 40 x 40 plane at y = 0 seen from 1.5 above at 50 degrees down, so that cos theta at the
/// plane runs from about 0.45 to 0.95 across the image; a constant white sky.
std::string skyPlaneScene(const std::string& material) {
  return R"({
    "camera": {"position": [0, 1.5, 0], "target": [0, 0.3, 1.0], "up": [0, 1, 0], "fov_y_deg": 40},
    "render": {"width": 32, "height": 32, "spp": 64, "max_depth": 8},
    "materials": {"m": )" + material + R"(},
    "shapes": [{"type": "quad", "material": "m", "vertices": [[-20, 0, -20], [-20, 0, 20], [20, 0, 20], [20, 0, -20]]}],
    "lights": [{"type": "environment", "radiance": [1, 1, 1]}]})";
}

/// The expected radiance of each 8 x 8 block: `radiance(cos)` at every pixel's centre, where
/// its camera ray meets the plane y = 0, averaged.
std::vector<double> blockExpectation(const Scene& scene, const std::function<double(float)>& radiance) {
  const int w = scene.render.width, h = scene.render.height;
  std::vector<double> out((w / 8) * (h / 8), 0.0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const Ray r = scene.camera.generateRay(float(x) + 0.5f, float(y) + 0.5f, w, h);
      const Vec3 d = glm::normalize(r.dir);
      out[(y / 8) * (w / 8) + x / 8] += radiance(std::fabs(d.y)) / 64.0;
    }
  return out;
}

std::vector<double> blockMeans(const Image& img) {
  std::vector<double> out((img.width / 8) * (img.height / 8), 0.0);
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) out[(y / 8) * (img.width / 8) + x / 8] += double(img.at(x, y).y) / 64.0;
  return out;
}

void expectBlocks(const Image& img, const std::vector<double>& want, double tol, const std::string& what) {
  const std::vector<double> got = blockMeans(img);
  ASSERT_EQ(got.size(), want.size());
  double worst = 0.0;
  for (size_t b = 0; b < got.size(); ++b) worst = std::max(worst, std::fabs(got[b] / want[b] - 1.0));
  report(what + " worst 8x8 block |ratio - 1|", worst, tol);
  for (size_t b = 0; b < got.size(); ++b)
    EXPECT_NEAR(got[b], want[b], tol * want[b]) << what << " block " << b << " (of " << got.size() << ")";
}

TEST(Coated, SmoothPlasticUnderASkyIsFresnelPlusTheAlbedoInEveryMethod) {
  const Scene scene = parseScene(skyPlaneScene(R"({"type": "plastic", "albedo": 0.5, "ior": 1.5})"), "plastic", ".");
  const auto want = blockExpectation(scene, [](float mu) {
    const float f = fresnelDielectric(mu, 1.5f);
    return double(f + (1.0f - f) * 0.5f);
  });
  // The coat alone is 4-10% of the light here: a method that dropped it fails by more than 3%.
  for (const char* method : {"path", "whitted", "voxcone", "pm"})
    expectBlocks(renderWith(scene, method, scene.render).image, want, 0.03, method);
}

TEST(Coated, RoughPlasticUnderASkyIsItsCoatPlusItsBaseInEveryMethod) {
  const Scene scene = parseScene(
      skyPlaneScene(R"({"type": "rough_plastic", "albedo": 0.5, "ior": 1.5, "roughness": 0.3})"), "roughplastic", ".");
  const Material& m = scene.materials[0];
  ASSERT_EQ(m.type, MaterialType::RoughPlastic);
  // Coat: 1 - T(mu) (its table, checked against the coat's lobe in test_bsdf); base: what enters,
  // T(mu), times albedo (1 - Fdr_ext) / (n^2 (1 - Fdr_int)).
  const double returned = 0.5 * (1.0 - m.coat.externalAlbedo) / (2.25 * (1.0 - m.coat.internalReflectance));
  const auto want = blockExpectation(scene, [&](float mu) {
    const float x = mu * float(CoatTable::kSize - 1);
    const int i = std::min(int(x), CoatTable::kSize - 2);
    const double t = (1.0 - (x - i)) * m.coat.transmittance[i] + (x - i) * m.coat.transmittance[i + 1];
    return (1.0 - t) + t * returned;
  });
  for (const char* method : {"path", "whitted", "voxcone", "pm"})
    expectBlocks(renderWith(scene, method, scene.render).image, want, 0.03, method);
}

TEST(Coated, AThinPanePassesWhatItsInterreflectionsLeave) {
  // A pane between the camera and an emitter of radiance 1, nothing else: 1 - R' at each pixel,
  // R' = 2F / (1 + F), undeflected (a refracting slab of one surface would bend the view).
  const Scene scene = parseScene(R"({
    "camera": {"position": [0, 0, 0], "target": [0, 0, 1], "up": [0, 1, 0], "fov_y_deg": 90},
    "render": {"width": 32, "height": 32, "spp": 16, "max_depth": 8},
    "materials": {"pane": {"type": "thin_dielectric", "ior": 1.5},
                  "lamp": {"type": "lambertian", "albedo": 0, "emission": [1, 1, 1], "two_sided_emission": true}},
    "shapes": [{"type": "quad", "material": "pane", "vertices": [[-50, -50, 1], [50, -50, 1], [50, 50, 1], [-50, 50, 1]]},
               {"type": "quad", "material": "lamp", "vertices": [[-500, -500, 2], [500, -500, 2], [500, 500, 2], [-500, 500, 2]]}],
    "lights": []})",
                                 "pane", ".");
  const int w = scene.render.width, h = scene.render.height;
  std::vector<double> want((w / 8) * (h / 8), 0.0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const Vec3 d = glm::normalize(scene.camera.generateRay(float(x) + 0.5f, float(y) + 0.5f, w, h).dir);
      const float f = fresnelDielectric(std::fabs(d.z), 1.5f);
      want[(y / 8) * (w / 8) + x / 8] += (1.0 - 2.0 * f / (1.0 + f)) / 64.0;
    }
  // Whitted follows both lobes; path picks one per sample (a Bernoulli of variance R'(1 - R'),
  // 1% is 4 standard errors of a block at 256 spp).
  expectBlocks(renderWith(scene, "whitted", scene.render).image, want, 0.01, "whitted");
  RenderSettings many = scene.render;
  many.spp = 256;
  expectBlocks(renderWith(scene, "path", many).image, want, 0.01, "path");
}

class CoatedFiles : public test::TempDirTest {};

TEST_F(CoatedFiles, WritersKeepTheNewMaterials) {
  const Scene scene = parseScene(R"({
    "camera": {"position": [0, 0, 4], "target": [0, 0, 0], "up": [0, 1, 0], "fov_y_deg": 40},
    "materials": {"p": {"type": "plastic", "albedo": [0.2, 0.3, 0.4], "ior": 1.6, "nonlinear": true, "two_sided": false},
                  "r": {"type": "rough_plastic", "albedo": 0.7, "specular": 0.9, "roughness": 0.25, "distribution": "beckmann"},
                  "t": {"type": "thin_dielectric", "ior": 1.33},
                  "l": {"type": "lambertian", "emission": [1, 1, 1]}},
    "shapes": [{"type": "quad", "material": "p", "vertices": [[-1, -1, 0], [0, -1, 0], [0, 0, 0], [-1, 0, 0]]},
               {"type": "quad", "material": "r", "vertices": [[0, -1, 0], [1, -1, 0], [1, 0, 0], [0, 0, 0]]},
               {"type": "quad", "material": "t", "vertices": [[-1, 0, 0], [0, 0, 0], [0, 1, 0], [-1, 1, 0]]},
               {"type": "quad", "material": "l", "vertices": [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]}],
    "lights": []})",
                                 "coated", ".");
  writeJsonScene(scene, path("a.json"));
  writeMitsubaScene(scene, path("a.xml"));
  float iorOff = 0.0f, colourOff = 0.0f;
  for (const Scene& back : {loadScene(path("a.json")), loadScene(path("a.xml"))}) {
    ASSERT_EQ(back.triangles.size(), scene.triangles.size());
    for (size_t t = 0; t < scene.triangles.size(); t += 2) {
      const Material& a = scene.materials[scene.triMaterial[t]];
      const Material& b = back.materials[back.triMaterial[t]];
      EXPECT_EQ(a.type, b.type) << a.name;
      if (a.isEmissive()) continue;
      EXPECT_NEAR(a.ior, b.ior, 1e-5f) << a.name;
      iorOff = std::max(iorOff, std::fabs(a.ior - b.ior));
      EXPECT_EQ(a.coatNonlinear, b.coatNonlinear) << a.name;
      EXPECT_EQ(a.twoSided, b.twoSided) << a.name;
      for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(a.albedo[c], b.albedo[c], 1e-6f) << a.name;
        EXPECT_NEAR(a.specular[c], b.specular[c], 1e-6f) << a.name;
        colourOff = std::max({colourOff, std::fabs(a.albedo[c] - b.albedo[c]), std::fabs(a.specular[c] - b.specular[c])});
      }
      if (a.type == MaterialType::RoughPlastic) {
        EXPECT_FLOAT_EQ(a.roughness, b.roughness);
        EXPECT_EQ(a.distribution, b.distribution);
      }
      // Prepared on load (Scene::finalize): the same tables.
      EXPECT_FLOAT_EQ(a.coat.internalReflectance, b.coat.internalReflectance) << a.name;
    }
  }
  report("worst ior error", iorOff, 1e-5);
  report("worst albedo or specular error", colourOff, 1e-6);
}

}  // namespace
}  // namespace voxcone

// The reference proven by what cannot share its mistakes: direct light against closed forms
// (Lambert's polygon formula, point lights) on planes at every coordinate magnitude and axis,
// the Cornell box region by region against the same closed form, invariance of the whole
// image under translation and rotation, and no ray ever re-hitting the surface it leaves.

#include "voxcone/accel/accel.h"
#include "voxcone/accel/hbvh.h"
#include "voxcone/core/error.h"
#include "voxcone/core/rng.h"
#include "voxcone/core/sampling.h"
#include "voxcone/integrator/integrator.h"
#include "voxcone/scene/generate.h"

#include "../support/render_helpers.h"
#include "../support/temp_dir.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

namespace voxcone {
namespace {

using test::lambertPolygonIrradiance;
using test::renderWith;

// ---------------------------------------------------------------------------------------------
// Closed forms

TEST(LambertFormula, MatchesHandComputedCases) {
  // A small square of area A facing p at distance d gives A / d^2; a huge one (a half-space)
  // gives pi.
  const std::vector<DVec3> small = {{-0.01, -0.01, 10}, {0.01, -0.01, 10}, {0.01, 0.01, 10}, {-0.01, 0.01, 10}};
  EXPECT_NEAR(lambertPolygonIrradiance(DVec3(0.0), DVec3(0, 0, 1), small), 4e-4 / 100.0, 1e-10);
  const std::vector<DVec3> huge = {{-1e7, -1e7, 1}, {1e7, -1e7, 1}, {1e7, 1e7, 1}, {-1e7, 1e7, 1}};
  EXPECT_NEAR(lambertPolygonIrradiance(DVec3(0.0), DVec3(0, 0, 1), huge), kPi, 1e-5);
  // The square [0,1]^2 at height 1 above a corner: the form factor of a unit square seen from
  // below one corner (Howell's catalogue, C-11 with a = b = c = 1) is 0.1385 * pi.
  const std::vector<DVec3> corner = {{0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
  // F = 1/(2 pi) [A/sqrt(1+A^2) atan(B/sqrt(1+A^2)) + B/sqrt(1+B^2) atan(A/sqrt(1+B^2))], A = B = 1.
  const double ff = 1.0 / (2.0 * kPi) * 2.0 * (1.0 / std::sqrt(2.0)) * std::atan(1.0 / std::sqrt(2.0));
  EXPECT_NEAR(lambertPolygonIrradiance(DVec3(0.0), DVec3(0, 0, 1), corner) / kPi, ff, 1e-9);
  EXPECT_NEAR(ff, 0.1385, 1e-4);
}

// ---------------------------------------------------------------------------------------------
// A Lambertian plane under one light, in any axis orientation at any coordinate magnitude

constexpr double kAlbedo = 0.5;
constexpr double kLightRadiance = 10.0;
constexpr double kLightHeight = 400.0;
constexpr double kLightHalfSide = 65.0;
constexpr double kPointIntensity = 2.0e5;

/// Plane-local (u, v, w) to world: w along world axis `axis`, (u, v, w) a cyclic permutation
/// of (x, y, z) (right-handed), everything shifted by `offset` on every axis.
struct PlaneFrame {
  int axis = 1;
  double offset = 0.0;
  DVec3 world(double u, double v, double w) const {
    DVec3 p;
    p[(axis + 1) % 3] = u + offset;
    p[(axis + 2) % 3] = v + offset;
    p[axis] = w + offset;
    return p;
  }
  DVec3 normal() const {
    DVec3 n(0.0);
    n[axis] = 1.0;
    return n;
  }
  std::vector<DVec3> light() const {
    const double s = kLightHalfSide;
    // Winding (-,-) (-,+) (+,+) (+,-): cross(v1 - v0, v2 - v0) points along -w, to the plane.
    return {world(-s, -s, kLightHeight), world(-s, s, kLightHeight), world(s, s, kLightHeight),
            world(s, -s, kLightHeight)};
  }
};

nlohmann::json jsonPoint(const DVec3& p) { return {p.x, p.y, p.z}; }

/// The plane (600 x 600, albedo kAlbedo) with a square area light (pointLight false) or a
/// point light kLightHeight above its centre.
Scene planeUnderLight(const PlaneFrame& f, bool pointLight) {
  nlohmann::json j;
  j["camera"] = {{"position", jsonPoint(f.world(0, 0, 200))}, {"target", jsonPoint(f.world(0, 0, 0))},
                 {"up", jsonPoint(f.world(1, 0, 0) - f.world(0, 0, 0))}, {"fov_y_deg", 90}};
  j["render"] = {{"width", 8}, {"height", 8}, {"spp", 1}};
  j["materials"]["white"] = {{"type", "lambertian"}, {"albedo", kAlbedo}};
  j["materials"]["light"] = {{"type", "lambertian"}, {"albedo", 0.0}, {"emission", kLightRadiance}};
  nlohmann::json plane = {{"type", "quad"}, {"name", "plane"}, {"material", "white"}};
  for (const DVec3& p : {f.world(-300, -300, 0), f.world(300, -300, 0), f.world(300, 300, 0), f.world(-300, 300, 0)})
    plane["vertices"].push_back(jsonPoint(p));
  j["shapes"].push_back(plane);
  if (pointLight) {
    j["lights"].push_back({{"type", "point"}, {"position", jsonPoint(f.world(0, 0, kLightHeight))},
                           {"intensity", kPointIntensity}});
  } else {
    nlohmann::json light = {{"type", "quad"}, {"name", "light"}, {"material", "light"}};
    for (const DVec3& p : f.light()) light["vertices"].push_back(jsonPoint(p));
    j["shapes"].push_back(light);
  }
  return parseScene(j.dump(), "plane-under-light", ".");
}

/// Mean and standard error of `n` estimates of integrator.li along `ray`, sample i drawn as
/// the render driver draws a pixel's sample i.
struct Estimate {
  double mean = 0.0, stdError = 0.0;
};
Estimate estimateAlong(const Integrator& integrator, const Ray& ray, int n, uint64_t stream) {
  Sampler sampler(SamplerKind::Sobol, 1, stream);
  double sum = 0.0, sum2 = 0.0;
  for (int i = 0; i < n; ++i) {
    sampler.startSample(uint32_t(i));
    sampler.uniform2();  // the pixel jitter's slot, as in renderImage
    const double l = integrator.li(ray, sampler).x;
    sum += l;
    sum2 += l * l;
  }
  Estimate e;
  e.mean = sum / n;
  e.stdError = std::sqrt(std::max(0.0, sum2 / n - e.mean * e.mean) / (n - 1));
  return e;
}

struct DirectCase {
  std::string method;
  bool pointLight;
};

class DirectLightOnPlanes : public ::testing::TestWithParam<DirectCase> {};

TEST_P(DirectLightOnPlanes, MatchesTheClosedFormAtEveryPointAxisAndOffset) {
  // Area light: within 0.1% at every point (1024 stratified samples; measured at most 2.5e-4,
  // where independent samples leave about 0.5% standard error). Point light: one
  // deterministic shadow ray, so within float rounding (1e-4). A self-hit of the shadow ray
  // shows as black, one of path's bounce ray as a missing MIS share.
  const DirectCase c = GetParam();
  const int samples = c.pointLight ? 4 : 1024;
  const double bound = c.pointLight ? 1e-4 : 1e-3;
  double worst = 0.0;
  int points = 0;
  for (int axis = 0; axis < 3; ++axis)
    for (double offset : {0.0, 1e-3, 1e3, 1e5}) {
      const PlaneFrame f{axis, offset};
      const Scene scene = planeUnderLight(f, c.pointLight);
      const Hbvh accel(scene);
      RenderSettings settings = scene.render;
      settings.maxDepth = 2;  // camera -> plane -> light: the direct part of path
      IntegratorContext ctx{scene, accel, settings, nlohmann::json::object()};
      const auto integrator = createIntegrator(c.method, ctx);
      integrator->prepare(nullptr);
      for (double u : {-250.0, -100.0, 0.0, 0.001, 120.0, 250.0})
        for (double v : {-250.0, -60.0, 0.0, 180.0, 250.0})
          for (const DVec3 eyeOffset : {DVec3(40.0, -25.0, 150.0), DVec3(900.0, -700.0, 350.0)}) {
            const DVec3 target = f.world(u, v, 0.0);
            // Seen from below the light: nearly overhead, and from afar at a slant (a hit point
            // taken as origin + t dir carries t times the ray's rounding).
            const DVec3 eye = f.world(u + eyeOffset.x, v + eyeOffset.y, eyeOffset.z);
            Ray ray;
            ray.origin = Vec3(eye);
            ray.dir = Vec3(glm::normalize(target - eye));
            SurfaceHit sh;
            ASSERT_TRUE(intersectSurface(scene, accel, ray, sh));
            const DVec3 p(sh.position);
            double exact;
            if (c.pointLight) {
              const DVec3 d = f.world(0, 0, kLightHeight) - p;
              exact = kAlbedo / kPi * kPointIntensity * glm::dot(f.normal(), glm::normalize(d)) / glm::dot(d, d);
            } else {
              exact = kAlbedo / kPi * kLightRadiance * lambertPolygonIrradiance(p, f.normal(), f.light());
            }
            const Estimate e = estimateAlong(*integrator, ray, samples, uint64_t(points));
            const double rel = std::fabs(e.mean / exact - 1.0);
            worst = std::max(worst, rel);
            EXPECT_LT(rel, bound) << c.method << " axis " << axis << " offset " << offset << " at (" << u << ", "
                                  << v << "): " << e.mean << " vs exact " << exact << " (std error " << e.stdError
                                  << ")";
            ++points;
          }
    }
  std::printf("%s, %s light: %d points, largest relative error %.2e\n", c.method.c_str(),
              c.pointLight ? "point" : "area", points, worst);
}

INSTANTIATE_TEST_SUITE_P(Reference, DirectLightOnPlanes,
                         ::testing::Values(DirectCase{"whitted", false}, DirectCase{"whitted", true},
                                           DirectCase{"path", false}, DirectCase{"path", true}),
                         [](const auto& info) {
                           return info.param.method + (info.param.pointLight ? "_point" : "_area");
                         });

// ---------------------------------------------------------------------------------------------
// N lights: the direct light is the sum of each light's closed form

/// The plane of planeUnderLight (axis y, at `offset`) under n small square lights in the plane
/// kLightHeight above it, one per cell of a sqrt(n) x sqrt(n) grid over [-200, 200]^2, each of a
/// random side (15% to 60% of its cell), place in its cell and colour (radiance 0.5 to 20 per
/// channel); one in four but the first faces up, away from the plane (it adds nothing, and the light choice
/// must learn that from its bounds). Lights in one plane cannot shadow each other from below.
struct ManyLights {
  Scene scene;
  std::vector<std::vector<DVec3>> down;  // the polygons facing the plane
  std::vector<DVec3> radiance;
};
ManyLights planeUnderLights(int n, const PlaneFrame& f, const std::string& sampler, double splitDeg) {
  nlohmann::json j;
  j["camera"] = {{"position", jsonPoint(f.world(0, 0, 200))}, {"target", jsonPoint(f.world(0, 0, 0))},
                 {"up", jsonPoint(f.world(1, 0, 0) - f.world(0, 0, 0))}, {"fov_y_deg", 90}};
  j["render"] = {{"width", 8}, {"height", 8}, {"spp", 1}, {"light_sampler", sampler}, {"light_split", splitDeg}};
  j["materials"]["white"] = {{"type", "lambertian"}, {"albedo", kAlbedo}};
  nlohmann::json plane = {{"type", "quad"}, {"name", "plane"}, {"material", "white"}};
  for (const DVec3& p : {f.world(-300, -300, 0), f.world(300, -300, 0), f.world(300, 300, 0), f.world(-300, 300, 0)})
    plane["vertices"].push_back(jsonPoint(p));
  j["shapes"].push_back(plane);
  ManyLights m;
  Rng rng(uint64_t(n), 1);
  const int side = int(std::lround(std::sqrt(double(n))));
  const double cell = 400.0 / side;
  for (int i = 0; i < n; ++i) {
    const double s = cell * (0.15 + 0.45 * rng.uniform());
    const double cu = -200.0 + cell * (i % side) + s / 2 + (cell - s) * rng.uniform();
    const double cv = -200.0 + cell * (i / side) + s / 2 + (cell - s) * rng.uniform();
    const DVec3 L(0.5 + 19.5 * rng.uniform(), 0.5 + 19.5 * rng.uniform(), 0.5 + 19.5 * rng.uniform());
    const bool up = rng.uniform() < 0.25 && i > 0;
    const double h = s / 2;
    // (-,-) (-,+) (+,+) (+,-) faces the plane (see PlaneFrame::light); reversed, away from it.
    std::vector<DVec3> poly = {f.world(cu - h, cv - h, kLightHeight), f.world(cu - h, cv + h, kLightHeight),
                               f.world(cu + h, cv + h, kLightHeight), f.world(cu + h, cv - h, kLightHeight)};
    if (up) std::reverse(poly.begin(), poly.end());
    const std::string mat = "lamp" + std::to_string(i);
    j["materials"][mat] = {{"type", "lambertian"}, {"albedo", 0.0}, {"emission", {L.x, L.y, L.z}}};
    nlohmann::json light = {{"type", "quad"}, {"name", mat}, {"material", mat}};
    for (const DVec3& p : poly) light["vertices"].push_back(jsonPoint(p));
    j["shapes"].push_back(light);
    if (!up) {
      m.down.push_back(poly);
      m.radiance.push_back(L);
    }
  }
  m.scene = parseScene(j.dump(), "plane-under-lights", ".");
  return m;
}

struct ManyLightsCase {
  std::string method;
  std::string sampler;
  double splitDeg = 0.0;  ///< the tree's split angle (0: none)
  int lightSamples = 1;   ///< the method's light_samples
};
class DirectLightFromNLights : public ::testing::TestWithParam<ManyLightsCase> {};

TEST_P(DirectLightFromNLights, EqualsTheSumOfEachLightsClosedForm) {
  // 1, 16 and 256 lights; at 12 points of the plane per count, 2048 stratified samples of the
  // direct light against sum_i albedo / pi * L_i * E_i (Lambert's formula per light), each
  // colour channel. Bound: 1% for 1 and 16 lights; for 256, where one sample sees one light,
  // 1.5% choosing by the tree and 3% by power (measured largest errors, printed: 0.004%, 0.35%,
  // 0.79% tree; 0.004%, 0.26%, 1.85% power; the tree splitting at 10 degrees, up to 16 lights
  // a sample: 0.004%, 0.04%, 0.07%; path with 4 light samples a vertex: 0.001%, 0.08%, 0.36%).
  const ManyLightsCase c = GetParam();
  for (int n : {1, 16, 256}) {
    double worst = 0.0;
    for (const PlaneFrame f : {PlaneFrame{1, 0.0}, PlaneFrame{0, 1e3}}) {
      const ManyLights m = planeUnderLights(n, f, c.sampler, c.splitDeg);
      const Hbvh accel(m.scene);
      RenderSettings settings = m.scene.render;
      settings.maxDepth = 2;
      IntegratorContext ctx{m.scene, accel, settings, {{"light_samples", c.lightSamples}}};
      const auto integrator = createIntegrator(c.method, ctx);
      integrator->prepare(nullptr);
      int point = 0;
      for (double u : {-250.0, -90.0, 0.0, 130.0})
        for (double v : {-170.0, 10.0, 240.0}) {
          const DVec3 target = f.world(u, v, 0.0);
          const DVec3 eye = f.world(u + 30.0, v - 20.0, 150.0);
          Ray ray;
          ray.origin = Vec3(eye);
          ray.dir = Vec3(glm::normalize(target - eye));
          SurfaceHit sh;
          ASSERT_TRUE(intersectSurface(m.scene, accel, ray, sh));
          const DVec3 p(sh.position);
          DVec3 exact(0.0);
          for (size_t i = 0; i < m.down.size(); ++i)
            exact += kAlbedo / kPi * m.radiance[i] * lambertPolygonIrradiance(p, f.normal(), m.down[i]);
          Sampler sampler(SamplerKind::Sobol, 1, uint64_t(point++));
          DVec3 sum(0.0);
          constexpr int kSamples = 2048;
          for (int s = 0; s < kSamples; ++s) {
            sampler.startSample(uint32_t(s));
            sampler.uniform2();  // the pixel jitter's slot
            sum += DVec3(integrator->li(ray, sampler));
          }
          for (int ch = 0; ch < 3; ++ch) {
            const double rel = std::fabs(sum[ch] / kSamples / exact[ch] - 1.0);
            worst = std::max(worst, rel);
            EXPECT_LT(rel, n < 256 ? 0.01 : c.sampler == "tree" ? 0.015 : 0.03) << c.method << " " << c.sampler << " split "
                                                 << c.splitDeg << ", " << n << " lights, axis "
                                                 << f.axis << " at (" << u << ", " << v << ") channel " << ch << ": "
                                                 << sum[ch] / kSamples << " vs exact " << exact[ch];
          }
        }
    }
    std::printf("%s, %s sampler, split %g: %d lights: largest relative error %.2e\n", c.method.c_str(),
                c.sampler.c_str(), c.splitDeg, n, worst);
  }
}

INSTANTIATE_TEST_SUITE_P(Reference, DirectLightFromNLights,
                         ::testing::Values(ManyLightsCase{"whitted", "tree"}, ManyLightsCase{"path", "tree"},
                                           ManyLightsCase{"whitted", "tree", 10.0}, ManyLightsCase{"path", "tree", 10.0},
                                           ManyLightsCase{"whitted", "power"}, ManyLightsCase{"path", "power"},
                                           ManyLightsCase{"path", "tree", 0.0, 4}),
                         [](const auto& info) {
                           return info.param.method + "_" + info.param.sampler +
                                  (info.param.splitDeg > 0.0 ? "_split" : "") +
                                  (info.param.lightSamples > 1 ? "_x" + std::to_string(info.param.lightSamples) : "");
                         });

// ---------------------------------------------------------------------------------------------
// The Cornell box, region by region

nlohmann::json cornellJson() {
  std::ifstream in(test::sourceDir() + "/data/scenes/cornell-box.json");
  return nlohmann::json::parse(in);
}

/// Per pixel of a w x h image of `scene`, the shape its centre ray hits (-1: none).
std::vector<int> regionMap(const Scene& scene, const Accel& accel, int w, int h) {
  std::vector<int> region(size_t(w) * h, -1);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      SurfaceHit sh;
      if (intersectSurface(scene, accel, scene.camera.generateRay(x + 0.5f, y + 0.5f, w, h), sh))
        region[size_t(y) * w + x] = int(scene.triShape[sh.triangle]);
    }
  return region;
}

TEST(CornellRegions, DirectLightOfEveryRegionMatchesLambertsFormula) {
  // whitted and path's direct part at the centre of every pixel of a 48x48 image that sees the
  // whole light (checked with 13x13 rays from the light, kept 1 mm off both surfaces so the
  // check shares no offset with the code under test), against Lambert's formula; each
  // region's mean ratio within 0.2%, every pixel within 1%; the ceiling, which the downward
  // light cannot reach, exactly black; the light itself exactly its radiance.
  const nlohmann::json j = cornellJson();
  const Scene scene = test::cornellBox();
  const Hbvh accel(scene);
  std::vector<DVec3> light;
  for (const auto& s : j["shapes"])
    if (s["name"] == "light")
      for (const auto& v : s["vertices"]) light.emplace_back(v[0].get<double>(), v[1].get<double>(), v[2].get<double>());
  ASSERT_EQ(light.size(), 4u);
  double lightRadiance = 0.0;
  for (const ShapeInfo& shape : scene.shapes)
    if (shape.name == "light") lightRadiance = scene.materials[scene.triMaterial[shape.firstTriangle]].emission.x;
  ASSERT_GT(lightRadiance, 0.0);
  constexpr int kRes = 48;
  const std::vector<int> region = regionMap(scene, accel, kRes, kRes);
  for (const std::string method : {"whitted", "path"}) {
    RenderSettings settings = scene.render;
    settings.maxDepth = 2;
    IntegratorContext ctx{scene, accel, settings, nlohmann::json::object()};
    const auto integrator = createIntegrator(method, ctx);
    integrator->prepare(nullptr);
    std::map<std::string, std::pair<double, int>> ratio;  // region -> (sum of ratios, pixels)
    int pixel = 0;
    for (int y = 0; y < kRes; ++y)
      for (int x = 0; x < kRes; ++x, ++pixel) {
        if (region[pixel] < 0) continue;
        const ShapeInfo& shape = scene.shapes[size_t(region[pixel])];
        const Ray ray = scene.camera.generateRay(x + 0.5f, y + 0.5f, kRes, kRes);
        SurfaceHit sh;
        ASSERT_TRUE(intersectSurface(scene, accel, ray, sh));
        const Material& mat = scene.materials[sh.material];
        if (shape.name == "light") {
          EXPECT_EQ(estimateAlong(*integrator, ray, 4, uint64_t(pixel)).mean, double(mat.emission.x));
          continue;
        }
        const Estimate e = estimateAlong(*integrator, ray, 512, uint64_t(pixel));
        if (shape.name == "ceiling") {
          EXPECT_EQ(e.mean, 0.0) << method << " ceiling pixel " << x << "," << y;
          continue;
        }
        // Is the whole light visible from here?
        const DVec3 p(sh.position);
        DVec3 n(sh.geomNormal);
        if (glm::dot(n, DVec3(ray.dir)) > 0.0) n = -n;
        bool visible = true;
        for (int a = 0; a <= 12 && visible; ++a)
          for (int b = 0; b <= 12 && visible; ++b) {
            const DVec3 q = light[0] + (light[1] - light[0]) * (a / 12.0) + (light[3] - light[0]) * (b / 12.0);
            if (glm::dot(q - p, n) <= 0.0) {
              visible = false;
              break;
            }
            const DVec3 from = q - DVec3(0, 1, 0);  // 1 mm below the light
            Ray r;
            r.origin = Vec3(from);
            r.dir = Vec3(p - from);
            r.tMax = float(1.0 - 1.0 / glm::length(p - from));
            visible = !accel.occluded(r);
          }
        if (!visible) continue;
        const double exact = double(mat.albedo.x) / kPi * lightRadiance * lambertPolygonIrradiance(p, n, light);
        const double r = e.mean / exact;
        EXPECT_NEAR(r, 1.0, 0.01) << method << " " << shape.name << " pixel " << x << "," << y << ": " << e.mean
                                  << " vs " << exact;
        auto& acc = ratio[shape.name];
        acc.first += r;
        acc.second += 1;
      }
    for (const std::string name : {"floor", "back_wall", "left_wall", "right_wall"}) {
      ASSERT_GT(ratio[name].second, 20) << method << " " << name << ": too few fully lit pixels";
    }
    for (const auto& [name, acc] : ratio) {
      if (acc.second < 5) continue;
      const double mean = acc.first / acc.second;
      std::printf("%s direct %-14s %4d px  mean ratio %.4f\n", method.c_str(), name.c_str(), acc.second, mean);
      EXPECT_NEAR(mean, 1.0, 0.002) << method << " region " << name;
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Invariances and an estimator without light sampling, region by region

/// Region means of two renders of the same w x h view, compared pixel set by pixel set (the
/// regions of `regions`): per region the mean of the per-pixel luminance difference, its
/// standard error (pixels are independent: each has its own sample stream), and the mean of a.
struct RegionDiff {
  std::string name;
  int pixels = 0;
  double meanA = 0.0, diff = 0.0, stdError = 0.0;
};
std::vector<RegionDiff> regionDiffs(const Scene& scene, const std::vector<int>& regions, const Image& a,
                                    const Image& b) {
  std::map<int, std::vector<std::pair<double, double>>> values;
  for (size_t i = 0; i < regions.size(); ++i)
    if (regions[i] >= 0) values[regions[i]].emplace_back(luminance(a.pixels[i]), luminance(b.pixels[i]));
  std::vector<RegionDiff> out;
  for (const auto& [shape, v] : values) {
    RegionDiff r;
    r.name = scene.shapes[size_t(shape)].name;
    r.pixels = int(v.size());
    double sd = 0.0, sd2 = 0.0;
    for (const auto& [x, y] : v) {
      r.meanA += x;
      sd += x - y;
      sd2 += (x - y) * (x - y);
    }
    r.meanA /= r.pixels;
    r.diff = sd / r.pixels;
    r.stdError = std::sqrt(std::max(0.0, sd2 / r.pixels - r.diff * r.diff) / std::max(1, r.pixels - 1));
    out.push_back(r);
  }
  return out;
}

/// Expect every region of at least 40 pixels to agree within 4.5 standard errors (30 or so
/// regions are tested in all, so a false alarm is unlikely), and the room's own surfaces (floor,
/// ceiling, walls: where the old bias sat) to have standard errors small enough that a change
/// of `detectable` (3%: the size of the bias this catches) would show.
void expectRegionsAgree(const std::vector<RegionDiff>& diffs, const std::string& what, double detectable = 0.03) {
  static const std::set<std::string> room = {"floor", "ceiling", "back_wall", "left_wall", "right_wall"};
  int tested = 0;
  for (const RegionDiff& r : diffs) {
    if (r.pixels < 40 || r.meanA <= 0.0) continue;
    ++tested;
    std::printf("%-22s %-14s %5d px  mean %.5f  diff %+.2f%%  (std error %.2f%%)\n", what.c_str(), r.name.c_str(),
                r.pixels, r.meanA, 100.0 * r.diff / r.meanA, 100.0 * r.stdError / r.meanA);
    EXPECT_LE(std::fabs(r.diff), 4.5 * r.stdError) << what << ": region " << r.name;
    if (room.count(r.name)) {
      EXPECT_LT(4.5 * r.stdError, detectable * r.meanA) << what << ": region " << r.name << " too noisy to test";
    }
  }
  EXPECT_GE(tested, 8) << what;
}

/// The cornell-box JSON with every vertex and the camera mapped by `point` (and `up` by
/// `vector`).
Scene transformedCornellBox(const std::function<DVec3(const DVec3&)>& point,
                            const std::function<DVec3(const DVec3&)>& vector) {
  nlohmann::json j = cornellJson();
  const auto map = [](nlohmann::json& v, const std::function<DVec3(const DVec3&)>& f) {
    const DVec3 p = f(DVec3(v[0].get<double>(), v[1].get<double>(), v[2].get<double>()));
    v = jsonPoint(p);
  };
  for (auto& shape : j["shapes"])
    for (auto& v : shape["vertices"]) map(v, point);
  map(j["camera"]["position"], point);
  map(j["camera"]["target"], point);
  map(j["camera"]["up"], vector);
  return parseScene(j.dump(), "cornell-box (transformed)", ".");
}

/// cornell-box at res x res and `spp`, the shape each pixel centre sees, and path's image.
struct CornellPath {
  Scene scene;
  RenderSettings settings;
  std::vector<int> regions;
  Image image;
};
CornellPath cornellPath(int res, int spp) {
  CornellPath c{test::cornellBox(), {}, {}, {}};
  c.settings = c.scene.render;
  c.settings.width = c.settings.height = res;
  c.settings.spp = spp;
  c.regions = regionMap(c.scene, Hbvh(c.scene), res, res);
  c.image = renderWith(c.scene, "path", c.settings).image;
  return c;
}

TEST(CornellRegions, TranslatedAndRotatedBoxesRenderTheSameImage) {
  // The box and camera moved by thousands of millimetres (to negative and positive
  // coordinates), and turned by 90 degrees about y and about x (exact in float): path's image
  // must not change region by region beyond noise. Surfaces near coordinate 0 were 25% dark
  // and moved 3% when moved away.
  const CornellPath base = cornellPath(96, 64);
  struct Case {
    std::string name;
    std::function<DVec3(const DVec3&)> point, vector;
  };
  const auto identity = [](const DVec3& v) { return v; };
  const std::vector<Case> cases = {
      {"translated", [](const DVec3& p) { return p + DVec3(-4321.0, 2750.0, 3900.0); }, identity},
      {"rotated about y", [](const DVec3& p) { return DVec3(p.z, p.y, -p.x); },
       [](const DVec3& v) { return DVec3(v.z, v.y, -v.x); }},
      {"rotated about x", [](const DVec3& p) { return DVec3(p.x, -p.z, p.y); },
       [](const DVec3& v) { return DVec3(v.x, -v.z, v.y); }},
  };
  for (const Case& c : cases) {
    const Scene moved = transformedCornellBox(c.point, c.vector);
    RenderSettings ms = base.settings;
    ms.seed = base.settings.seed + 1;
    expectRegionsAgree(regionDiffs(base.scene, base.regions, base.image, renderWith(moved, "path", ms).image), c.name);
  }
}

TEST(CornellRegions, PathAgreesWithBsdfSamplingAloneInEveryRegion) {
  // Path tracing without light sampling shares no light sampling, MIS or shadow ray with the
  // default; both are unbiased, so every region (walls, floor, ceiling, block faces) must agree
  // within noise. The BSDF-only estimate is noisy (the light is small): 1024 spp at 48x48 still
  // leaves 1-1.5% standard error on the room's surfaces, so a 7% difference is what shows.
  const CornellPath nee = cornellPath(48, 256);
  RenderSettings s = nee.settings;
  s.spp = 1024;
  s.seed = 7;
  const Image bsdfOnly = renderWith(nee.scene, "path", s, {{"light_sampling", "none"}}).image;
  expectRegionsAgree(regionDiffs(nee.scene, nee.regions, nee.image, bsdfOnly), "nee vs bsdf-only", 0.07);
}

// ---------------------------------------------------------------------------------------------
// No self-hits

/// Whether triangle b lies in the plane of triangle a (the other half of a planar quad, which a
/// ray leaving a can only hit by re-hitting its own surface).
bool coplanar(const Scene& scene, uint32_t a, uint32_t b) {
  const UVec3& ta = scene.triangles[a];
  const DVec3 p0(scene.positions[ta.x]), p1(scene.positions[ta.y]), p2(scene.positions[ta.z]);
  const DVec3 n = glm::normalize(glm::cross(p1 - p0, p2 - p0));
  const double scale = std::max({glm::length(p1 - p0), glm::length(p2 - p0), 1e-30});
  for (int k = 0; k < 3; ++k)
    if (std::fabs(glm::dot(n, DVec3(scene.positions[scene.triangles[b][k]]) - p0)) > 1e-6 * scale) return false;
  return true;
}

/// Self-hits among about `rays` rays spawned from random hit points of `scene`: a third leave
/// to the side the hit came from (reflection), a third to the other side (transmission), a
/// third are shadow rays to a sampled light point; a quarter of the first two graze the surface
/// (1e-3 from the tangent plane).
uint64_t countSelfHits(const Scene& scene, uint64_t rays, uint64_t& spawned) {
  const Hbvh accel(scene);
  const Bounds3 b = scene.bounds();
  uint64_t selfHits = 0;
  spawned = 0;
  Rng rng(99, 0);
  while (spawned < rays) {
    Ray probe;
    probe.origin = b.lo + (b.hi - b.lo) * Vec3(rng.uniform(), rng.uniform(), rng.uniform());
    probe.dir = sampleUniformSphere(rng.uniform2());
    SurfaceHit sh;
    if (!intersectSurface(scene, accel, probe, sh)) continue;
    const Vec3 front = glm::dot(sh.geomNormal, probe.dir) < 0.0f ? sh.geomNormal : -sh.geomNormal;
    const auto isSelf = [&](const std::optional<Hit>& h) {
      return h && (h->triangle == sh.triangle || coplanar(scene, sh.triangle, h->triangle));
    };
    for (const float side : {1.0f, -1.0f}) {
      const Vec3 n = side * front;
      Vec3 d = sampleUniformSphere(rng.uniform2());
      if (glm::dot(d, n) < 0.0f) d = -d;
      if (rng.uniform() < 0.25f) d = glm::normalize(glm::normalize(d - glm::dot(d, n) * n) + 1e-3f * n);
      if (!isFinite(d)) continue;
      selfHits += isSelf(accel.intersect(spawnRay(sh.position, sh.positionError, sh.geomNormal, d)));
      ++spawned;
    }
    if (scene.hasLights()) {
      const LightSample ls = scene.sampleLight(sh.position, rng.uniform2());
      if (ls.pdf > 0.0f) {
        const Ray r = spawnRayTo(sh.position, sh.positionError, sh.geomNormal, ls.lightPos, ls.lightPosError,
                                 ls.lightNormal);
        selfHits += isSelf(accel.intersect(r));
        ++spawned;
      }
    }
  }
  return selfHits;
}

class SpawnedRaysTest : public test::TempDirTest {};

TEST_F(SpawnedRaysTest, NeverHitTheirOwnSurfaceInAnyCanonicalScene) {
  // A million rays per scene: every scene of data/scenes whose meshes are here (the dragon
  // scenes need tools/fetch_models.sh), and a generated 20k-triangle knot in the Cornell room
  // standing in for a curved mesh when the dragon is not.
  std::vector<std::pair<std::string, Scene>> scenes;
  for (const auto& entry : std::filesystem::directory_iterator(test::sourceDir() + "/data/scenes")) {
    if (entry.path().extension() != ".json") continue;
    try {
      scenes.emplace_back(entry.path().stem().string(), loadScene(entry.path().string()));
    } catch (const Error& e) {
      std::printf("skipped %s: %s\n", entry.path().filename().c_str(), e.what());
    }
  }
  writePly(path("knot.ply"), makeKnotMesh(20000));
  nlohmann::json j = cornellJson();
  j["shapes"].push_back({{"type", "mesh"}, {"name", "knot"}, {"material", "white"}, {"file", path("knot.ply")},
                         {"transform", {{"scale", 40.0}, {"translate", {278.0, 200.0, 280.0}}}}});
  scenes.emplace_back("cornell-knot", parseScene(j.dump(), "cornell-knot", "."));
  ASSERT_GE(scenes.size(), 3u);
  for (const auto& [name, scene] : scenes) {
    uint64_t spawned = 0;
    const uint64_t selfHits = countSelfHits(scene, 1000000, spawned);
    std::printf("%-26s %8llu rays spawned, %llu self-hits\n", name.c_str(), (unsigned long long)spawned,
                (unsigned long long)selfHits);
    EXPECT_EQ(selfHits, 0u) << name;
  }
}

}  // namespace
}  // namespace voxcone

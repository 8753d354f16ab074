#pragma once
// Rendering a scene with an integrator by name, for the integrator tests.

#include "voxcone/accel/hbvh.h"
#include "voxcone/core/parallel.h"
#include "voxcone/image/metrics.h"
#include "voxcone/integrator/integrator.h"

#include "test_scenes.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

namespace voxcone::test {

/// Build the HBVH, create `method` with `options`, prepare it and render `settings`.
inline RenderResult renderWith(const Scene& scene, const std::string& method, RenderSettings settings,
                               nlohmann::json options = nlohmann::json::object()) {
  const Hbvh accel(scene);
  settings.method = method;
  IntegratorContext ctx{scene, accel, settings, options};
  auto integrator = createIntegrator(method, ctx);
  integrator->prepare(nullptr);
  return renderImage(scene, *integrator, settings);
}

/// Mean of columns [x0, x1) of `img` (x1 < 0: up to the width), over all rows.
inline Vec3 imageMean(const Image& img, int x0 = 0, int x1 = -1) {
  if (x1 < 0) x1 = img.width;
  DVec3 s(0.0);
  for (int y = 0; y < img.height; ++y)
    for (int x = x0; x < x1; ++x) s += DVec3(img.pixels[size_t(y) * img.width + x]);
  return Vec3(s / double(size_t(img.height) * size_t(x1 - x0)));
}

/// Pixels that differ between renders at 1 and 2 threads (0 when rendering is deterministic).
inline size_t pixelsDifferingAcrossThreads(const Scene& scene, const std::string& method, const RenderSettings& s,
                                           const nlohmann::json& options = nlohmann::json::object()) {
  Image images[2];
  for (int threads : {1, 2}) {
    ThreadLimit limit(threads);
    images[threads - 1] = renderWith(scene, method, s, options).image;
  }
  if (images[0].pixels.size() != images[1].pixels.size()) return images[0].pixels.size() + images[1].pixels.size();
  size_t diff = 0;
  for (size_t i = 0; i < images[0].pixels.size(); ++i) diff += images[0].pixels[i] != images[1].pixels[i];
  return diff;
}

/// Rec. 709 luminance.
inline double luminance(const DVec3& c) { return 0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z; }

/// The largest |ratio - 1| of a 4 x 4 cell's mean luminance, `test` against `reference`.
inline double worstCellDeviation(const Image& test, const Image& reference) {
  double w = 0.0;
  for (const RegionError& e : regionErrors(test, reference, 4))
    w = std::max(w, std::fabs(luminance(e.meanTest) / luminance(e.meanReference) - 1.0));
  return w;
}

/// The canonical Cornell box of data/scenes.
inline Scene cornellBox() { return loadScene(sourceDir() + "/data/scenes/cornell-box.json"); }

/// Image means of cornell-box at 32x32: `method` with `options` at 16 spp, and path tracing at
/// 1024 spp (the converged value the other methods are held to).
struct CornellMeans {
  Vec3 method, path;
};
inline CornellMeans cornellBoxMeans(const std::string& method, const nlohmann::json& options) {
  const Scene scene = cornellBox();
  RenderSettings s = scene.render;
  s.width = s.height = 32;
  s.spp = 1024;
  CornellMeans m;
  m.path = imageMean(renderWith(scene, "path", s).image);
  s.spp = 16;
  m.method = imageMean(renderWith(scene, method, s, options).image);
  return m;
}

/// Each 4 x 4 cell's mean luminance (Rec. 709), voxcone's default render over path's at
/// `pathSpp` (both at the scene's own resolution, voxcone at its spp; path's seed apart from
/// voxcone's), row-major from the top.
inline std::vector<double> cellRatiosAgainstPath(const Scene& scene, int pathSpp = 64) {
  RenderSettings p = scene.render;
  p.spp = pathSpp;
  p.seed = 1234;
  const Image path = renderWith(scene, "path", p).image;
  const Image vc = renderWith(scene, "voxcone", scene.render).image;
  const auto luminance = [](const DVec3& v) { return 0.2126 * v.x + 0.7152 * v.y + 0.0722 * v.z; };
  std::vector<double> ratios;
  for (const RegionError& c : regionErrors(vc, path, 4)) ratios.push_back(luminance(c.meanTest) / luminance(c.meanReference));
  return ratios;
}

}  // namespace voxcone::test

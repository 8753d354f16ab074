// What the light tree costs per shading point, next to choosing by power: at the first hits of a
// scene's camera rays (default: the failure suite's 16-light room), the light samples
// (Scene::sampleLights: the choice and the point on the light; with splitting one per group),
// the same with their shadow rays (direct light as path and voxcone take it), and the pmf
// path's MIS recomputes for a light a BSDF sample hits.
//   ./build-bench/bench/light_tree_bench [--benchmark_filter=...] [scene.json]

#include "voxcone/accel/hbvh.h"
#include "voxcone/core/rng.h"
#include "voxcone/integrator/integrator.h"
#include "voxcone/scene/light_tree.h"
#include "voxcone/scene/scene.h"

#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace {

using namespace voxcone;

struct Fixture {
  Scene scene;
  std::unique_ptr<Hbvh> accel;
  std::vector<SurfaceHit> points;  // first hits of a 64 x 64 grid of camera rays
};

std::string g_scenePath = VOXCONE_SOURCE_DIR "/data/scenes/failure/many-lights.json";

Fixture& fixture() {
  static Fixture f = [] {
    Fixture x;
    x.scene = loadScene(g_scenePath);
    x.accel = std::make_unique<Hbvh>(x.scene);
    for (int y = 0; y < 64; ++y)
      for (int px = 0; px < 64; ++px) {
        SurfaceHit sh;
        if (intersectSurface(x.scene, *x.accel, x.scene.camera.generateRay(px + 0.5f, y + 0.5f, 64, 64), sh) &&
            !x.scene.materials[sh.material].isEmissive())
          x.points.push_back(sh);
      }
    std::printf("%s: %zu shading points, %zu emissive triangles\n", g_scenePath.c_str(), x.points.size(),
                x.scene.emissiveTriangleCount());
    return x;
  }();
  return f;
}

/// The scene's light choice as a benchmark argument: 0 power, 1 the tree, 2 the tree splitting
/// at 45 degrees.
const char* setSampler(Fixture& f, int64_t sampler) {
  f.scene.setLightTree(sampler != 0);
  f.scene.setLightSplit(sampler == 2 ? 45.0f : 0.0f);
  return sampler == 0 ? "power" : sampler == 1 ? "tree" : "tree, split 45";
}

void BM_LightSample(benchmark::State& state) {
  // Per shading point: the lights' samples (Scene::sampleLights: one, or one per group where
  // the tree splits) and, with range(1), a shadow ray to each.
  Fixture& f = fixture();
  const char* label = setSampler(f, state.range(0));
  const bool shadowRays = state.range(1) != 0;
  Rng rng(1, 0);
  size_t i = 0;
  int64_t lights = 0;
  for (auto _ : state) {
    const SurfaceHit& sh = f.points[i++ % f.points.size()];
    LightSample ls[LightTree::kMaxChoices];
    const int n = f.scene.sampleLights(sh.position, rng.uniform2(), true, nullptr, &sh.shadingNormal, ls);
    lights += n;
    for (int k = 0; k < n; ++k) {
      bool occluded = !(ls[k].pdf > 0.0f);
      if (shadowRays && !occluded)
        occluded = f.accel->occluded(
            spawnRayTo(sh.position, sh.positionError, sh.geomNormal, ls[k].lightPos, ls[k].lightPosError, ls[k].lightNormal));
      benchmark::DoNotOptimize(occluded);
    }
  }
  state.counters["lights_per_point"] = double(lights) / double(std::max<int64_t>(1, state.iterations()));
  state.SetLabel(std::string(label) + (shadowRays ? ", shadow rays" : ""));
}
BENCHMARK(BM_LightSample)->ArgsProduct({{0, 1, 2}, {0, 1}});

void BM_LightPdf(benchmark::State& state) {
  // The MIS pdf of a light point found by a BSDF ray (what path computes then): per shading
  // point one light point drawn and its triangle found by a ray, before the timing.
  Fixture& f = fixture();
  const char* label = setSampler(f, state.range(0));
  struct Found {
    size_t point;
    uint32_t triangle;
    Vec3 position, normal;
  };
  std::vector<Found> found;
  Rng rng(1, 0);
  for (size_t i = 0; i < f.points.size(); ++i) {
    const SurfaceHit& sh = f.points[i];
    const LightSample ls = f.scene.sampleLight(sh.position, rng.uniform2(), true, nullptr, &sh.shadingNormal);
    if (!(ls.pdf > 0.0f) || ls.delta) continue;
    if (const std::optional<Hit> hit = f.accel->intersect(spawnRay(sh.position, sh.positionError, sh.geomNormal, ls.wi)))
      found.push_back({i, hit->triangle, ls.lightPos, ls.lightNormal});
  }
  if (found.empty()) {
    state.SkipWithError("no light point in sight");
    return;
  }
  size_t k = 0;
  for (auto _ : state) {
    const Found& x = found[k++ % found.size()];
    const SurfaceHit& sh = f.points[x.point];
    benchmark::DoNotOptimize(f.scene.lightPdf(sh.position, &sh.shadingNormal, x.triangle, x.position, x.normal));
  }
  state.SetLabel(label);
}
BENCHMARK(BM_LightPdf)->Arg(0)->Arg(1)->Arg(2);

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (argc > 1) g_scenePath = argv[1];
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}

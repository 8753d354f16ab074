#include "voxcone/core/error.h"
#include "voxcone/core/timer.h"
#include "voxcone/integrator/integrator.h"

#include <tbb/parallel_for.h>

#include <atomic>

namespace voxcone {

RenderResult renderImage(const Scene& scene, const Integrator& integrator, const RenderSettings& settings,
                         Progress* progress) {
  settings.validate();
  constexpr int kTile = 16;
  const int w = settings.width, h = settings.height;
  const int tilesX = (w + kTile - 1) / kTile, tilesY = (h + kTile - 1) / kTile;
  RenderResult result;
  result.image = Image(w, h);
  std::atomic<uint64_t> invalid{0};
  std::atomic<bool> cancelled{false};
  if (progress) progress->start("render", static_cast<uint64_t>(tilesX) * tilesY);
  Timer timer;
  tbb::parallel_for(0, tilesX * tilesY, [&](int tile) {
    if (cancelled.load(std::memory_order_relaxed)) return;
    if (progress && progress->cancelled()) {
      cancelled = true;
      return;
    }
    const int x0 = (tile % tilesX) * kTile, y0 = (tile / tilesX) * kTile;
    uint64_t bad = 0;
    for (int y = y0; y < std::min(y0 + kTile, h); ++y)
      for (int x = x0; x < std::min(x0 + kTile, w); ++x) {
        Sampler sampler(settings.sampler, settings.seed,
                        static_cast<uint64_t>(y) * static_cast<uint64_t>(w) + static_cast<uint64_t>(x),
                        static_cast<uint32_t>(settings.spp));
        // Sum in double so the mean does not depend on float rounding of a long sum.
        DVec3 sum(0.0);
        for (int s = 0; s < settings.spp; ++s) {
          sampler.startSample(static_cast<uint32_t>(s));
          const Vec2 jitter = sampler.uniform2();
          const Ray ray = scene.camera.generateRay(static_cast<float>(x) + jitter.x, static_cast<float>(y) + jitter.y, w, h);
          const Vec3 L = integrator.li(ray, sampler);
          if (!isFinite(L) || L.x < 0.0f || L.y < 0.0f || L.z < 0.0f) {
            ++bad;
            continue;
          }
          sum += DVec3(L);
        }
        result.image.at(x, y) = Vec3(sum / double(settings.spp));
      }
    invalid += bad;
    if (progress) progress->advance(1);
  });
  if (cancelled) throw CancelledError();
  if (progress) progress->finish();
  result.seconds = timer.seconds();
  result.samples = static_cast<uint64_t>(w) * h * settings.spp;
  result.invalidSamples = invalid;
  return result;
}

}  // namespace voxcone

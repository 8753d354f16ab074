// What the denoiser costs: the RT network (rt_hdr_alb_nrm.tza, tools/fetch_models.sh) on a
// random HDR image with albedo and normal, at 256x256 and 1024x1024, per convolution kernel
// (avx2, generic) and thread count; Gflop/s counts the 3x3 convolutions' multiply-adds as two
// operations, the padded channels included.
//   ./build-bench/bench/denoise_bench [--benchmark_filter=...]

#include "voxcone/core/parallel.h"
#include "voxcone/core/rng.h"
#include "voxcone/denoise/denoiser.h"

#include <benchmark/benchmark.h>

#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

namespace {

using namespace voxcone;

const Denoiser* denoiser() {
  static const std::unique_ptr<Denoiser> d = []() -> std::unique_ptr<Denoiser> {
    const std::string path = VOXCONE_SOURCE_DIR "/data/models/oidn/rt_hdr_alb_nrm.tza";
    if (!std::filesystem::exists(path)) return nullptr;
    return std::make_unique<Denoiser>(readTza(path), 9);
  }();
  return d.get();
}

/// Multiply-adds of the network per pixel of a padded image: full, 1/4, 1/16, 1/64, 1/256
/// resolution, with the channels padded to blocks of 8 (16 and 80 inputs, 8 outputs).
double macsPerPixel() {
  const double l0 = 9.0 * (16 * 32 + 32 * 32 + 80 * 64 + 64 * 32 + 32 * 8);
  const double l1 = 9.0 * (32 * 48 + 128 * 64 + 64 * 64) / 4;
  const double l2 = 9.0 * (48 * 64 + 160 * 96 + 96 * 96) / 16;
  const double l3 = 9.0 * (64 * 80 + 160 * 112 + 112 * 112) / 64;
  const double l4 = 9.0 * (80 * 96 + 96 * 96) / 256;
  return l0 + l1 + l2 + l3 + l4;
}

void BM_Denoise(benchmark::State& state) {
  const Denoiser* base = denoiser();
  if (!base) {
    state.SkipWithError("no weights: bash tools/fetch_models.sh");
    return;
  }
  const int size = int(state.range(0));
  const std::vector<std::string> kernels = Denoiser::kernels();
  if (size_t(state.range(1)) >= kernels.size()) {
    state.SkipWithError("kernel not on this CPU");
    return;
  }
  Denoiser d(readTza(VOXCONE_SOURCE_DIR "/data/models/oidn/rt_hdr_alb_nrm.tza"), 9);
  d.setKernel(kernels[size_t(state.range(1))]);
  const ThreadLimit threads(int(state.range(2)));
  Image color(size, size), albedo(size, size), normal(size, size, Vec3(0.0f, 0.0f, 1.0f));
  Rng rng(1, 0);
  for (size_t p = 0; p < color.pixels.size(); ++p) {
    color.pixels[p] = Vec3(rng.uniform(), rng.uniform(), rng.uniform()) * 2.0f;
    albedo.pixels[p] = Vec3(0.5f);
  }
  DenoiseTimings t;
  double network = 0.0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(d.denoise(color, &albedo, &normal, &t));
    network += t.network;
  }
  state.SetLabel(d.kernel() + ", " + std::to_string(threads.threads()) + " threads");
  state.counters["network_s"] = network / double(state.iterations());
  state.counters["Gflop/s"] = 2.0 * macsPerPixel() * double(size) * double(size) / (network / double(state.iterations())) / 1e9;
}
BENCHMARK(BM_Denoise)
    ->ArgsProduct({{256, 1024}, {0, 1}, {1, 2}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(0.5);

}  // namespace

BENCHMARK_MAIN();

// render --target-error / --time-budget: voxcone in averaged passes with a self-estimated error
// (auto_settings.h).

#include "voxcone/integrator/auto_settings.h"

#include "voxcone/core/error.h"
#include "voxcone/core/rng.h"
#include "voxcone/core/timer.h"
#include "voxcone/image/metrics.h"
#include "voxcone/integrator/voxel_cone/voxel_cone.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace voxcone {

namespace {

/// One control pixel per kControlBlock x kControlBlock block: 1024 at 256x256, whose spatial
/// sampling of the bias is about 9% (BiasEstimateMatchesAKnownBias: 64 pixels at 64x64, 15%).
constexpr int kControlBlock = 8;

std::string fmt(const char* f, double v) {
  char b[64];
  std::snprintf(b, sizeof b, f, v);
  return b;
}

/// The control pixels: one per block, its place in the block from the seed (deterministic).
std::vector<size_t> controlPixels(int width, int height, uint64_t seed) {
  std::vector<size_t> pixels;
  for (int by = 0; by < height; by += kControlBlock)
    for (int bx = 0; bx < width; bx += kControlBlock) {
      const uint64_t h = mixBits(seed ^ (uint64_t(by) << 32 | uint64_t(bx)) ^ 0x636f6e74726f6cull);
      const int bw = std::min(kControlBlock, width - bx), bh = std::min(kControlBlock, height - by);
      const int x = bx + int(h % uint64_t(bw)), y = by + int((h >> 32) % uint64_t(bh));
      pixels.push_back(size_t(y) * size_t(width) + size_t(x));
    }
  return pixels;
}

/// The running estimates over the passes so far.
struct Estimates {
  double noise = 0.0;      ///< one pass's relMSE against its expectation
  double bias2 = 0.0;      ///< mean squared relative bias, clamped at 0
  double bias2Raw = 0.0;   ///< before clamping (may be negative from noise)
  double bias2Error = 0.0; ///< standard error of bias2Raw
  double predicted(int passes) const { return noise / double(passes) + bias2; }
};

}  // namespace

ProgressiveResult renderVoxconeToTarget(const Scene& scene, const Accel& accel, const RenderSettings& settings,
                                        const ProgressiveRequest& req, Progress* progress) {
  const bool byError = req.targetRelMse > 0.0, byTime = req.timeBudget > 0.0;
  if (byError == byTime) throw SettingsError("give one of --target-error and --time-budget, with a positive value");
  if (!(std::isfinite(req.targetRelMse) && std::isfinite(req.timeBudget)))
    throw SettingsError("--target-error and --time-budget must be finite");
  if (!req.options.is_object()) throw SettingsError("voxcone options must be a JSON object");
  if (req.passSpp < 1 || req.controlSpp < 1 || req.maxPasses < 2)
    throw SettingsError("a progressive render needs spp >= 1 per pass and at least 2 passes");
  Timer total;
  ProgressiveResult r;
  const size_t n = size_t(settings.width) * size_t(settings.height);
  std::vector<DVec3> sum(n, DVec3(0.0)), sumSquares(n, DVec3(0.0));
  const std::vector<size_t> control = controlPixels(settings.width, settings.height, settings.seed);
  std::vector<PixelSamples> controlSamples(control.size());
  std::unique_ptr<Integrator> path;
  {
    RenderSettings ps = settings;
    ps.method = "path";
    path = createIntegrator("path", IntegratorContext{scene, accel, ps, nlohmann::json::object()});
    path->prepare(nullptr);
  }
  nlohmann::json history = nlohmann::json::array();
  Estimates est;
  double passSeconds = 0.0;  // every pass's prepare, render and control pixels
  uint64_t optionSeed = 0;  // voxcone's `seed` option: its photon seed is the pass seed plus it
  std::string stopReason;
  RenderSettings pass = settings;
  pass.method = "voxcone";
  pass.spp = req.passSpp;
  for (int k = 0; k < req.maxPasses; ++k) {
    if (progress && progress->cancelled()) throw CancelledError();
    Timer passTimer;
    pass.seed = settings.seed + uint64_t(k);
    // One integrator for every pass: its voxels are kept, its photons traced anew per pass
    // (the photon seed follows the pass's seed as it would in a render with that seed).
    Timer t;
    if (!r.integrator) {
      r.integrator = createIntegrator("voxcone", IntegratorContext{scene, accel, pass, req.options});
      r.integrator->prepare(nullptr);
      optionSeed = static_cast<VoxelConeIntegrator&>(*r.integrator).settings().photons.seed - pass.seed;
    } else {
      static_cast<VoxelConeIntegrator&>(*r.integrator).reseed(pass.seed + optionSeed, nullptr);
    }
    r.prepareSeconds += t.seconds();
    RenderResult img = renderImage(scene, *r.integrator, pass, progress);
    for (size_t p = 0; p < n; ++p) {
      const DVec3 v(img.image.pixels[p]);
      sum[p] += v;
      sumSquares[p] += v * v;
    }
    r.result.samples += img.samples;
    r.result.invalidSamples += img.invalidSamples;
    r.result.seconds += img.seconds;
    for (const auto& [stage, sec] : img.stageSeconds.items())
      r.result.stageSeconds[stage] = r.result.stageSeconds.value(stage, 0.0) + sec.get<double>();
    r.result.filterStats = img.filterStats;
    // The control pixels, path traced with this pass's seed, until bias2 is known well enough.
    const double errorScale = byError ? req.targetRelMse : est.predicted(std::max(2, r.passes));
    const bool controlDone = r.passes >= 2 && est.bias2Error < 0.05 * errorScale;
    t.reset();
    if (!controlDone) {
    RenderSettings cs = pass;
    cs.method = "path";
    cs.spp = req.controlSpp;
    cs.seed = mixBits(pass.seed ^ 0x7061746863746c31ull);
    // The render's own (stratified) sampler, one estimate per pass: the passes' estimates are
    // independent (randomized quasi-Monte Carlo), so their spread gives the variance of their
    // mean. (The spread of the stratified samples within a pass overstates it: the bias estimate
    // came out -0.006 +- 0.001 on cornell-box; independent samples were unbiased but noisier.)
    const std::vector<PixelSamples> c = renderPixels(scene, *path, cs, control);
    for (size_t i = 0; i < control.size(); ++i) {
      if (c[i].count == 0) continue;
      const DVec3 mean = c[i].sum / double(c[i].count);
      controlSamples[i].sum += mean;
      controlSamples[i].sumSquares += mean * mean;
      ++controlSamples[i].count;
    }
    }
    r.controlSeconds += t.seconds();
    r.passes = k + 1;
    passSeconds += passTimer.seconds();
    if (r.passes < 2) continue;

    // The estimates from all passes so far.
    const double K = double(r.passes);
    double noiseSum = 0.0;
    std::vector<double> passVariance(n * 3);  // one pass's variance per pixel and channel
    for (size_t p = 0; p < n; ++p)
      for (int ch = 0; ch < 3; ++ch) {
        const double m = sum[p][ch] / K;
        const double var = std::max(0.0, (sumSquares[p][ch] - K * m * m) / (K - 1.0));
        passVariance[p * 3 + size_t(ch)] = var;
        noiseSum += var / (m * m + kRelMseEpsilon);
      }
    est.noise = noiseSum / double(3 * n);
    double b = 0.0, b2 = 0.0;
    size_t terms = 0;
    for (size_t i = 0; i < control.size(); ++i) {
      const PixelSamples& cp = controlSamples[i];
      if (cp.count < 2) continue;
      double term = 0.0;
      for (int ch = 0; ch < 3; ++ch) {
        const double m = sum[control[i]][ch] / K;
        const double pm = cp.sum[ch] / cp.count;
        const double varP = std::max(0.0, (cp.sumSquares[ch] - cp.count * pm * pm) / (cp.count - 1.0)) / cp.count;  // of the mean of the passes' estimates
        const double varM = passVariance[control[i] * 3 + size_t(ch)] / K;
        term += ((m - pm) * (m - pm) - varM - varP) / (m * m + kRelMseEpsilon);
      }
      term /= 3.0;
      b += term;
      b2 += term * term;
      ++terms;
    }
    if (terms > 1) {
      est.bias2Raw = b / double(terms);
      est.bias2Error = std::sqrt(std::max(0.0, b2 / double(terms) - est.bias2Raw * est.bias2Raw) / double(terms - 1));
    }
    est.bias2 = std::max(0.0, est.bias2Raw);
    const double meanPass = passSeconds / K;
    history.push_back({{"passes", r.passes}, {"noise_per_pass", est.noise}, {"bias2", est.bias2Raw},
                       {"bias2_standard_error", est.bias2Error}, {"predicted_relmse", est.predicted(r.passes)},
                       {"seconds", total.seconds()}});
    if (byError) {
      // Beyond two standard errors below the bias no number of passes reaches the target.
      if (req.targetRelMse < est.bias2Raw - 2.0 * est.bias2Error)
        throw SettingsError("--target-error " + fmt("%.3g", req.targetRelMse) +
                            " is below voxcone's estimated squared bias " + fmt("%.3g", est.bias2Raw) + " (+- " +
                            fmt("%.2g", est.bias2Error) + ", relMSE, from " + std::to_string(terms) +
                            " path-traced control pixels): more passes cannot reach it; ask for at least " +
                            fmt("%.3g", 1.25 * est.bias2Raw));
      // Passes for the target over the bias plus one standard error (a short render's two
      // passes know the bias to +-0.0004 on cornell-box), the margin at least a tenth of the
      // target (a bias estimated just under it would ask for unbounded passes).
      const double margin = std::max(req.targetRelMse - est.bias2 - est.bias2Error, 0.1 * req.targetRelMse);
      const int needed = int(std::min<double>(req.maxPasses, std::ceil(est.noise / margin)));
      if (r.passes >= needed) {
        stopReason = "target";
        break;
      }
    } else {
      if (total.seconds() + meanPass > req.timeBudget) {
        stopReason = "budget";
        break;
      }
    }
  }
  if (stopReason.empty()) stopReason = "max_passes";

  const double K = double(r.passes);
  r.result.image = Image(settings.width, settings.height);
  for (size_t p = 0; p < n; ++p) r.result.image.pixels[p] = Vec3(sum[p] / K);
  r.noise = est.noise;
  r.bias2 = est.bias2;
  r.predictedRelMse = est.predicted(r.passes);
  r.met = byError ? r.predictedRelMse <= req.targetRelMse : total.seconds() <= req.timeBudget;
  const double controlShare = passSeconds > 0.0 ? r.controlSeconds / passSeconds : 0.0;
  r.report = {{"target_relmse", byError ? nlohmann::json(req.targetRelMse) : nlohmann::json()},
              {"time_budget_seconds", byTime ? nlohmann::json(req.timeBudget) : nlohmann::json()},
              {"met", r.met},
              {"stopped_by", stopReason},
              {"chosen", {{"passes", r.passes}, {"pass_spp", req.passSpp}, {"spp", r.passes * req.passSpp}}},
              {"predicted_relmse", r.predictedRelMse},
              {"predicted_terms", {{"noise", est.noise / K}, {"bias2", est.bias2}}},
              {"noise_per_pass", est.noise},
              {"bias2_raw", est.bias2Raw},
              {"bias2_standard_error", est.bias2Error},
              {"control", {{"pixels", control.size()}, {"block", kControlBlock}, {"spp_per_pass", req.controlSpp},
                           {"seconds", r.controlSeconds}, {"share_of_passes", controlShare}}},
              {"history", history}};
  r.summary = std::string(r.met ? "rendered " : "stopped at ") + std::to_string(r.passes) + " passes of " +
              std::to_string(req.passSpp) + " spp (" + stopReason + ")\n" + "  predicted relMSE " +
              fmt("%.4g", r.predictedRelMse) + " = noise " + fmt("%.3g", est.noise) + " / " + std::to_string(r.passes) +
              " passes + bias^2 " + fmt("%.3g", est.bias2) + " (+- " + fmt("%.2g", est.bias2Error) + ")" +
              (byError ? " (target " + fmt("%.4g", req.targetRelMse) + ")" : std::string()) + "\n" + "  " +
              fmt("%.2f", total.seconds()) + " s" +
              (byTime ? " (budget " + fmt("%.2f", req.timeBudget) + " s)" : std::string()) + ", control pixels " +
              fmt("%.3f", r.controlSeconds) + " s (" + fmt("%.1f", 100.0 * controlShare) + "% of the passes)\n";
  return r;
}

}  // namespace voxcone

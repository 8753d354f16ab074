// render --target-error / --time-budget: voxcone in averaged passes with a self-estimated error
// (progressive.h).

#include "voxcone/integrator/progressive.h"

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
  size_t controlTerms = 0; ///< control pixels behind bias2Raw (those with 2 or more passes)
  double predicted(int passes) const { return noise / double(passes) + bias2; }
};

/// Throws SettingsError unless `req` asks for one of a target and a budget, finite, with
/// samples in every pass and room for two passes.
void checkRequest(const ProgressiveRequest& req) {
  const bool byError = req.targetRelMse > 0.0, byTime = req.timeBudget > 0.0;
  if (byError == byTime) throw SettingsError("give one of --target-error and --time-budget, with a positive value");
  if (!(std::isfinite(req.targetRelMse) && std::isfinite(req.timeBudget)))
    throw SettingsError("--target-error and --time-budget must be finite");
  if (!req.options.is_object()) throw SettingsError("voxcone options must be a JSON object");
  if (req.passSpp < 1 || req.controlSpp < 1 || req.maxPasses < 2)
    throw SettingsError("a progressive render needs spp >= 1 per pass and at least 2 passes");
}

/// Add a pass's counts and times to the passes' (its filter statistics replace theirs).
void addPassStats(RenderResult& passes, const RenderResult& pass) {
  passes.samples += pass.samples;
  passes.invalidSamples += pass.invalidSamples;
  passes.seconds += pass.seconds;
  for (const auto& [stage, sec] : pass.stageSeconds.items())
    passes.stageSeconds[stage] = passes.stageSeconds.value(stage, 0.0) + sec.get<double>();
  passes.filterStats = pass.filterStats;
}

/// A progressive render: its passes, their per-pixel sums, the control pixels' path-traced
/// estimates, and the estimates of error they give after every pass (progressive.h).
class ProgressiveRender {
public:
  ProgressiveRender(const Scene& scene, const Accel& accel, const RenderSettings& settings,
                    const ProgressiveRequest& req, Progress* progress)
      : m_scene(scene), m_accel(accel), m_settings(settings), m_req(req), m_progress(progress),
        m_byError(req.targetRelMse > 0.0), m_byTime(req.timeBudget > 0.0),
        m_pixels(size_t(settings.width) * size_t(settings.height)), m_sum(m_pixels, DVec3(0.0)),
        m_sumSquares(m_pixels, DVec3(0.0)), m_control(controlPixels(settings.width, settings.height, settings.seed)),
        m_controlSamples(m_control.size()) {
    RenderSettings ps = settings;
    ps.method = "path";
    m_path = createIntegrator("path", IntegratorContext{scene, accel, ps, nlohmann::json::object()});
    m_path->prepare(nullptr);
  }

  /// Passes until the target, the budget or maxPasses; the mean image, the report and the
  /// summary.
  ProgressiveResult run() {
    std::string stopReason;
    RenderSettings pass = m_settings;
    pass.method = "voxcone";
    pass.spp = m_req.passSpp;
    for (int k = 0; k < m_req.maxPasses && stopReason.empty(); ++k) {
      if (m_progress && m_progress->cancelled()) throw CancelledError();
      Timer passTimer;
      pass.seed = m_settings.seed + uint64_t(k);
      renderPass(pass);
      // The control pixels, path traced with this pass's seed, until bias2 is known well enough.
      const double errorScale = m_byError ? m_req.targetRelMse : m_est.predicted(std::max(2, m_r.passes));
      const bool controlDone = m_r.passes >= 2 && m_est.bias2Error < 0.05 * errorScale;
      Timer t;
      if (!controlDone) addControlSamples(pass);
      m_r.controlSeconds += t.seconds();
      m_r.passes = k + 1;
      m_passSeconds += passTimer.seconds();
      if (m_r.passes < 2) continue;
      estimate();
      m_history.push_back({{"passes", m_r.passes}, {"noise_per_pass", m_est.noise}, {"bias2", m_est.bias2Raw},
                           {"bias2_standard_error", m_est.bias2Error},
                           {"predicted_relmse", m_est.predicted(m_r.passes)}, {"seconds", m_total.seconds()}});
      stopReason = stopAfterThisPass();
    }
    if (stopReason.empty()) stopReason = "max_passes";
    finish(stopReason);
    return std::move(m_r);
  }

private:
  /// One pass at `pass`'s seed: one integrator for every pass, its voxels kept, its photons
  /// traced anew per pass (the photon seed follows the pass's seed as it would in a render
  /// with that seed); its image added to the sums.
  void renderPass(const RenderSettings& pass) {
    Timer t;
    if (!m_r.integrator) {
      m_r.integrator = createIntegrator("voxcone", IntegratorContext{m_scene, m_accel, pass, m_req.options});
      m_r.integrator->prepare(nullptr);
      m_optionSeed = static_cast<VoxelConeIntegrator&>(*m_r.integrator).settings().photons.seed - pass.seed;
    } else {
      static_cast<VoxelConeIntegrator&>(*m_r.integrator).reseed(pass.seed + m_optionSeed, nullptr);
    }
    m_r.prepareSeconds += t.seconds();
    RenderResult img = renderImage(m_scene, *m_r.integrator, pass, m_progress);
    for (size_t p = 0; p < m_pixels; ++p) {
      const DVec3 v(img.image.pixels[p]);
      m_sum[p] += v;
      m_sumSquares[p] += v * v;
    }
    addPassStats(m_r.result, img);
  }

  /// One path-traced estimate per control pixel for `pass`.
  void addControlSamples(const RenderSettings& pass) {
    RenderSettings cs = pass;
    cs.method = "path";
    cs.spp = m_req.controlSpp;
    cs.seed = mixBits(pass.seed ^ 0x7061746863746c31ull);
    // The render's own (stratified) sampler, one estimate per pass: the passes' estimates are
    // independent (randomized quasi-Monte Carlo), so their spread gives the variance of their
    // mean. (The spread of the stratified samples within a pass overstates it: the bias estimate
    // came out -0.006 +- 0.001 on cornell-box; independent samples were unbiased but noisier.)
    const std::vector<PixelSamples> c = renderPixels(m_scene, *m_path, cs, m_control);
    for (size_t i = 0; i < m_control.size(); ++i) {
      if (c[i].count == 0) continue;
      const DVec3 mean = c[i].sum / double(c[i].count);
      m_controlSamples[i].sum += mean;
      m_controlSamples[i].sumSquares += mean * mean;
      ++m_controlSamples[i].count;
    }
  }

  /// The estimates from all passes so far (two or more).
  void estimate() {
    const double K = double(m_r.passes);
    // One pass's relMSE against its expectation, from the passes' spread.
    double noiseSum = 0.0;
    std::vector<double> passVariance(m_pixels * 3);  // one pass's variance per pixel and channel
    for (size_t p = 0; p < m_pixels; ++p)
      for (int ch = 0; ch < 3; ++ch) {
        const double m = m_sum[p][ch] / K;
        const double var = std::max(0.0, (m_sumSquares[p][ch] - K * m * m) / (K - 1.0));
        passVariance[p * 3 + size_t(ch)] = var;
        noiseSum += var / (m * m + kRelMseEpsilon);
      }
    m_est.noise = noiseSum / double(3 * m_pixels);
    // The squared bias: each control pixel's (M - P)^2 less both means' variances.
    double b = 0.0, b2 = 0.0;
    size_t terms = 0;
    for (size_t i = 0; i < m_control.size(); ++i) {
      const PixelSamples& cp = m_controlSamples[i];
      if (cp.count < 2) continue;
      double term = 0.0;
      for (int ch = 0; ch < 3; ++ch) {
        const double m = m_sum[m_control[i]][ch] / K;
        const double pm = cp.sum[ch] / cp.count;
        const double varP = std::max(0.0, (cp.sumSquares[ch] - cp.count * pm * pm) / (cp.count - 1.0)) / cp.count;  // of the mean of the passes' estimates
        const double varM = passVariance[m_control[i] * 3 + size_t(ch)] / K;
        term += ((m - pm) * (m - pm) - varM - varP) / (m * m + kRelMseEpsilon);
      }
      term /= 3.0;
      b += term;
      b2 += term * term;
      ++terms;
    }
    if (terms > 1) {
      m_est.bias2Raw = b / double(terms);
      m_est.bias2Error = std::sqrt(std::max(0.0, b2 / double(terms) - m_est.bias2Raw * m_est.bias2Raw) / double(terms - 1));
    }
    m_est.bias2 = std::max(0.0, m_est.bias2Raw);
    m_est.controlTerms = terms;
  }

  /// "target" or "budget" where the passes so far meet it, else "". Throws SettingsError for a
  /// target below the estimated bias.
  std::string stopAfterThisPass() const {
    if (!m_byError) {
      const double meanPass = m_passSeconds / double(m_r.passes);
      return m_total.seconds() + meanPass > m_req.timeBudget ? "budget" : "";
    }
    // Beyond two standard errors below the bias no number of passes reaches the target.
    if (m_req.targetRelMse < m_est.bias2Raw - 2.0 * m_est.bias2Error)
      throw SettingsError("--target-error " + fmt("%.3g", m_req.targetRelMse) +
                          " is below voxcone's estimated squared bias " + fmt("%.3g", m_est.bias2Raw) + " (+- " +
                          fmt("%.2g", m_est.bias2Error) + ", relMSE, from " + std::to_string(m_est.controlTerms) +
                          " path-traced control pixels): more passes cannot reach it; ask for at least " +
                          fmt("%.3g", 1.25 * m_est.bias2Raw));
    // Passes for the target over the bias plus one standard error (a short render's two
    // passes know the bias to +-0.0004 on cornell-box), the margin at least a tenth of the
    // target (a bias estimated just under it would ask for unbounded passes).
    const double margin = std::max(m_req.targetRelMse - m_est.bias2 - m_est.bias2Error, 0.1 * m_req.targetRelMse);
    const int needed = int(std::min<double>(m_req.maxPasses, std::ceil(m_est.noise / margin)));
    return m_r.passes >= needed ? "target" : "";
  }

  /// The mean image, the final estimates, the report for the sidecar and the console summary.
  void finish(const std::string& stopReason) {
    const double K = double(m_r.passes);
    m_r.result.image = Image(m_settings.width, m_settings.height);
    for (size_t p = 0; p < m_pixels; ++p) m_r.result.image.pixels[p] = Vec3(m_sum[p] / K);
    m_r.noise = m_est.noise;
    m_r.bias2 = m_est.bias2;
    m_r.predictedRelMse = m_est.predicted(m_r.passes);
    m_r.met = m_byError ? m_r.predictedRelMse <= m_req.targetRelMse : m_total.seconds() <= m_req.timeBudget;
    const double controlShare = m_passSeconds > 0.0 ? m_r.controlSeconds / m_passSeconds : 0.0;
    m_r.report = {
        {"target_relmse", m_byError ? nlohmann::json(m_req.targetRelMse) : nlohmann::json()},
        {"time_budget_seconds", m_byTime ? nlohmann::json(m_req.timeBudget) : nlohmann::json()},
        {"met", m_r.met},
        {"stopped_by", stopReason},
        {"chosen", {{"passes", m_r.passes}, {"pass_spp", m_req.passSpp}, {"spp", m_r.passes * m_req.passSpp}}},
        {"predicted_relmse", m_r.predictedRelMse},
        {"predicted_terms", {{"noise", m_est.noise / K}, {"bias2", m_est.bias2}}},
        {"noise_per_pass", m_est.noise},
        {"bias2_raw", m_est.bias2Raw},
        {"bias2_standard_error", m_est.bias2Error},
        {"control", {{"pixels", m_control.size()}, {"block", kControlBlock}, {"spp_per_pass", m_req.controlSpp},
                     {"seconds", m_r.controlSeconds}, {"share_of_passes", controlShare}}},
        {"history", m_history}};
    m_r.summary = std::string(m_r.met ? "rendered " : "stopped at ") + std::to_string(m_r.passes) + " passes of " +
                  std::to_string(m_req.passSpp) + " spp (" + stopReason + ")\n" + "  predicted relMSE " +
                  fmt("%.4g", m_r.predictedRelMse) + " = noise " + fmt("%.3g", m_est.noise) + " / " +
                  std::to_string(m_r.passes) + " passes + bias^2 " + fmt("%.3g", m_est.bias2) + " (+- " +
                  fmt("%.2g", m_est.bias2Error) + ")" +
                  (m_byError ? " (target " + fmt("%.4g", m_req.targetRelMse) + ")" : std::string()) + "\n" + "  " +
                  fmt("%.2f", m_total.seconds()) + " s" +
                  (m_byTime ? " (budget " + fmt("%.2f", m_req.timeBudget) + " s)" : std::string()) +
                  ", control pixels " + fmt("%.3f", m_r.controlSeconds) + " s (" +
                  fmt("%.1f", 100.0 * controlShare) + "% of the passes)\n";
  }

  const Scene& m_scene;
  const Accel& m_accel;
  const RenderSettings& m_settings;
  const ProgressiveRequest& m_req;
  Progress* m_progress;
  const bool m_byError, m_byTime;
  Timer m_total;
  ProgressiveResult m_r;
  const size_t m_pixels;
  std::vector<DVec3> m_sum, m_sumSquares;  ///< per pixel, over the passes
  const std::vector<size_t> m_control;     ///< the control pixels
  std::vector<PixelSamples> m_controlSamples;  ///< per control pixel, one path-traced mean per pass
  std::unique_ptr<Integrator> m_path;      ///< renders the control pixels
  Estimates m_est;
  nlohmann::json m_history = nlohmann::json::array();
  double m_passSeconds = 0.0;  ///< every pass's prepare, render and control pixels
  uint64_t m_optionSeed = 0;   ///< voxcone's `seed` option: its photon seed is the pass seed plus it
};

}  // namespace

ProgressiveResult renderVoxconeToTarget(const Scene& scene, const Accel& accel, const RenderSettings& settings,
                                        const ProgressiveRequest& req, Progress* progress) {
  checkRequest(req);
  return ProgressiveRender(scene, accel, settings, req, progress).run();
}

}  // namespace voxcone

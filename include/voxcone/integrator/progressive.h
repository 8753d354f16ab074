#pragma once
/// \file progressive.h
/// `voxcone render --target-error E | --time-budget S`: voxcone rendered in independent passes
/// until the predicted error meets the target or the budget is spent.
///
/// A pass is a whole voxcone render at `passSpp` (the defaults' 4 unless --spp is given) with
/// its own pixel seed (seed + k) and photon seed; the image is the mean of the passes. Each pass
/// traces new photons into the same voxelization (VoxelConeIntegrator::reseed), so photon noise,
/// the gathers' noise and the direct light's all average out over the passes, and nothing a
/// pass computes is thrown away: the pilot is the passes themselves plus a few path-traced
/// control pixels. The prediction for K passes against the true image is
///   relMSE(K) = noise / K + bias2
///  - noise: one pass's relMSE against its own expectation, from the passes' spread: per pixel
///    and channel sum_k (I_k - M)^2 / (K - 1), over (M^2 + eps), averaged (eps as relMSE's);
///  - bias2: voxcone's mean squared bias against the true image. Control pixels (one in each 8x8
///    block, chosen per block from the seed) are path traced, `controlSpp` stratified samples
///    per pass with a new seed each pass: one unbiased, independent estimate per pass
///    (randomized quasi-Monte Carlo). Per control pixel (M - P)^2 - var(M) - var(P) over
///    (M^2 + eps), with var(P) and var(M) from the passes' spread, is an unbiased estimate of its
///    squared relative bias, and their mean estimates bias2. Passes
///    stop adding control samples once bias2's standard error is below 5% of the target (or
///    of the prediction, for a budget): the control costs most where the render is short.
/// After every pass both are re-estimated and the passes needed are recomputed, for the target
/// less bias2 and its standard error (conservative where the bias is known poorly); a target below
/// bias2 cannot be met by more passes (a SettingsError after the first two, which say so); a
/// budget takes as many passes as the mean pass time leaves room for (at least two).

#include "voxcone/core/progress.h"
#include "voxcone/integrator/integrator.h"
#include "voxcone/scene/scene.h"

#include <nlohmann/json.hpp>

#include <memory>
#include <string>

namespace voxcone {

class Accel;

struct ProgressiveRequest {
  double targetRelMse = 0.0;  ///< > 0: stop once the predicted relMSE is at most this
  double timeBudget = 0.0;    ///< > 0: seconds left for the passes (the caller has spent the rest)
  nlohmann::json options = nlohmann::json::object();  ///< voxcone options, every pass
  int passSpp = 4;            ///< samples per pixel of one pass
  int controlSpp = 14;        ///< path samples per control pixel per pass
  int maxPasses = 1024;
};

struct ProgressiveResult {
  /// The mean of the passes: image, samples (all passes'), seconds (the passes' pixel loops),
  /// stage seconds summed over the passes.
  RenderResult result;
  std::unique_ptr<Integrator> integrator;  ///< the last pass's (its settings and statistics)
  int passes = 0;
  double prepareSeconds = 0.0;   ///< every pass's prepare (photons, voxels, mips)
  double controlSeconds = 0.0;   ///< the control pixels (the pilot's only extra cost)
  double predictedRelMse = 0.0;  ///< noise / passes + bias2, at the end
  double noise = 0.0, bias2 = 0.0;
  bool met = false;              ///< target: predicted <= target; budget: the passes fit it
  nlohmann::json report;         ///< estimates after every pass, for the sidecar
  std::string summary;           ///< a few lines for the console
};

/// Render voxcone progressively for `request` (one of target and budget, positive); `settings`
/// gives resolution, seed, sampler and max depth. Deterministic for a given seed at any thread
/// count (the stopping decision depends on the images only, for a target; a budget's pass count
/// depends on time). Throws SettingsError for a bad request or a target below the estimated
/// bias, CancelledError when `progress` is cancelled.
ProgressiveResult renderVoxconeToTarget(const Scene& scene, const Accel& accel, const RenderSettings& settings,
                                        const ProgressiveRequest& request, Progress* progress = nullptr);

}  // namespace voxcone

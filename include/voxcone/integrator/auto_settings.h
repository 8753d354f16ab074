#pragma once
/// \file auto_settings.h
/// `voxcone render --target-error E | --time-budget S`: voxcone's voxel level, photon counts,
/// cone count and samples per pixel chosen for the scene from a quick pilot pass.
///
/// The pilot renders the scene at a quarter of the resolution (4 spp) six times and at the full
/// resolution (1 spp) twice, and splits voxcone's error into four terms that it can measure
/// without a reference, each from two pilots that differ in one thing only:
///   pixel noise      a / spp    (two pixel seeds, the same photons; full resolution),
///   photon noise     b / P      (two photon sets of P0 and 4 P0 photons, the same pixel seeds),
///   level bias       c(L)       (levels 5, 6, 7 against 8, the same seeds),
///   cone bias        d(C)       (6 cones against 16).
/// Predicted relMSE = a/spp + b/P + c(L) + d(C), against voxcone's own converged image: the
/// method's bias against the true image (what a path-traced reference shows) is not predicted.
/// Time is predicted from the pilots' prepare times (per level; per photon from the two photon
/// counts) and render times (per pixel sample, per level and cone count). The choice is the
/// fastest setting whose predicted error meets the target, or the most accurate whose
/// predicted time fits the budget.

#include "voxcone/core/progress.h"
#include "voxcone/scene/scene.h"

#include <nlohmann/json.hpp>

namespace voxcone {

class Accel;

struct AutoSettingsRequest {
  double targetRelMse = 0.0;  ///< > 0: meet this predicted relMSE in the least time
  double timeBudget = 0.0;    ///< > 0: least predicted error within this many seconds (pilot included)
  /// voxcone options the user gave: a given level, photons or cones is kept, not chosen.
  nlohmann::json fixedOptions = nlohmann::json::object();
  int fixedSpp = 0;           ///< > 0: keep this spp
};

struct AutoSettingsResult {
  nlohmann::json options;        ///< voxcone options to render with (fixed ones included)
  int spp = 0;
  double predictedRelMse = 0.0;
  double predictedSeconds = 0.0; ///< prepare + render at the full resolution
  double pilotSeconds = 0.0;
  bool met = false;              ///< false: nothing met the target / fit the budget (closest chosen)
  nlohmann::json report;         ///< the measured terms, the pilots and the choice, for the sidecar
  std::string summary;           ///< what was chosen and why, a few lines for the console
};

/// Run the pilot and choose. `settings` is the full render's (resolution, seed, max depth, the
/// scene's photon defaults). Throws SettingsError for a request with neither or both of
/// target and budget, or a non-positive one.
AutoSettingsResult chooseVoxconeSettings(const Scene& scene, const Accel& accel, const RenderSettings& settings,
                                         const AutoSettingsRequest& request, Progress* progress = nullptr);

}  // namespace voxcone

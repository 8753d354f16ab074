#pragma once
/// \file study.h
/// Studies over batches of renders against a reference (speed-accuracy, photons, levels): the
/// manifest of each, its renders run here or as a Slurm job array, and its table (one row per
/// successful render, Pareto fronts in time and relMSE, equal-time and equal-error comparisons
/// with path's front).

#include "voxcone/batch/batch.h"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace voxcone {

/// A sweep study's settings.
struct SweepSettings {
  std::string kind;           ///< "speed-accuracy", "photons" or "levels"
  std::string scenePath;
  std::string referencePath;
  std::string resolution;     ///< WIDTHxHEIGHT, the reference's
  bool quick = false;         ///< a few cheap settings (tests)
  /// speed-accuracy: path and voxcone denoised too (`render --denoise`), each a front of its
  /// own ("path+denoise", "voxcone+denoise"); the CLI sets it where the weights are fetched.
  bool denoise = false;
  std::vector<int64_t> photons;  ///< levels: photon counts as a second axis (empty: the scene's)
};

/// The study's renders as a batch manifest. speed-accuracy: every method over its settings (path
/// spp; pm photons; voxcone level x photons x cones x spp); photons: pm and voxcone over photon
/// counts; levels: voxcone over voxel levels (x photon counts when given).
nlohmann::json sweepManifest(const SweepSettings& settings);

/// Where a study's renders run: here, or as a Slurm job array (submitted, waited for, merged).
struct StudyScheduler {
  bool slurm = false;
  SlurmSettings cluster;
};

/// A study's renders: `manifest` written to outDir/manifest.json and run as a resumable batch
/// (finished renders kept) into outDir/runs, here or on Slurm; returns {"rows": ...}, one row per
/// job (resultRow), the same rows either way. CancelledError on SIGINT / SIGTERM.
nlohmann::json runStudyRenders(const nlohmann::json& manifest, const std::string& outDir, const BatchSettings& batch,
                               const StudyScheduler& scheduler = {});

/// Indices of the Pareto front of `pts` (time, error), both minimized: the points no other point
/// beats on both; sorted by time.
std::vector<size_t> paretoFront(const std::vector<std::pair<double, double>>& pts);
/// y at x on a front (sorted by x), log-log linear between its points; NaN outside it.
double onFront(const std::vector<std::pair<double, double>>& front, double x);

/// A sweep study's table from its batch rows: "rows" (one per render that succeeded with
/// metrics: method, spp, photons, level, seconds, relMSE, MSE, PSNR, memory, Pareto flag) and
/// "comparisons" (each pm / voxcone front point and every voxcone-auto render against path's
/// front at equal time and equal error).
nlohmann::json sweepTable(const nlohmann::json& batchRows);

/// The table's rows as CSV at `path` (atomic).
void writeSweepCsv(const nlohmann::json& rows, const std::string& path);

}  // namespace voxcone

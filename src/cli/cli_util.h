#pragma once
// Helpers of the subcommands: option checks, and running voxcone itself in child processes
// (study, batch).

#include "voxcone/batch/process.h"

#include <CLI/CLI.hpp>
#include <nlohmann/json_fwd.hpp>

#include <cstdint>

#include <string>

namespace voxcone {

/// CLI11 check: the value must not be empty (an empty --method or -o would otherwise mean
/// "not given" and silently fall back to a default).
const CLI::Validator& nonEmpty();
/// CLI11 check: a finite number above zero (CLI::PositiveNumber printed DBL_MAX's 309 digits).
const CLI::Validator& positiveNumber();

/// A seed: a decimal integer in [0, 2^64 - 1]; anything else (a sign, a fraction, more than 64
/// bits) is a SettingsError naming `option`, never clamped.
uint64_t parseSeed(const std::string& option, const std::string& text);



/// Where a study's batch runs: here, or as a Slurm job array (`batch --slurm --wait`, then its
/// --merge), with these submission settings.
struct StudyScheduler {
  bool slurm = false;
  std::string partition;  ///< --partition, "" for the cluster's default
  std::string timeLimit;  ///< --time per task, "" for the partition's
  int shards = 0;         ///< array tasks, 0: one per job
};

/// A study's renders: write `manifest` to outDir/manifest.json, run it as a resumable batch
/// (`voxcone batch --skip-existing`, finished renders kept) into outDir/runs, here or on Slurm,
/// and return its results.json (the batch's, or the shards' merged: the same rows). Failed jobs
/// are in the rows; throws Error when the batch itself fails.
nlohmann::json runStudyBatch(const nlohmann::json& manifest, const std::string& outDir, int jobsInFlight,
                             int threadsPerJob, const StudyScheduler& scheduler = {});

/// Add --slurm, --partition, --time and --shards to a study command.
void addSchedulerOptions(CLI::App& cmd, StudyScheduler& scheduler);

/// Run a chart script (python3-matplotlib) on STUDY.json writing OUT_STEM.{png,svg}; prints
/// what it says. Throws Error with its first line when it fails.
void runChartScript(const std::string& script, const std::string& studyJson, const std::string& outStem);

}  // namespace voxcone

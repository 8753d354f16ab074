#pragma once
// Helpers of the subcommands that run voxcone itself in child processes (study, batch).

#include <nlohmann/json_fwd.hpp>

#include <string>

namespace voxcone {

/// `s` quoted for /bin/sh.
std::string shellQuote(const std::string& s);

/// Run `cmd` through /bin/sh and capture its stdout; returns the exit status (-1 when it did
/// not exit normally). Throws Error when it cannot be started.
int runCapture(const std::string& cmd, std::string& out);

/// Path of the running voxcone executable.
std::string selfExe();

/// A study's renders: write `manifest` to outDir/manifest.json, run it as a resumable batch
/// (`voxcone batch --skip-existing`, finished renders kept) into outDir/runs, and return its
/// results.json. Failed jobs are in the rows; throws Error when the batch itself fails.
nlohmann::json runStudyBatch(const nlohmann::json& manifest, const std::string& outDir, int jobsInFlight,
                             int threadsPerJob);

/// Run a chart script (python3-matplotlib) on STUDY.json writing OUT_STEM.{png,svg}; prints
/// what it says. Throws Error with its first line when it fails.
void runChartScript(const std::string& script, const std::string& studyJson, const std::string& outStem);

}  // namespace voxcone

#pragma once
// Helpers of the subcommands: option checks, and running voxcone itself in child processes
// (study, batch).

#include "voxcone/batch/process.h"
#include "voxcone/batch/study.h"
#include "voxcone/denoise/denoiser.h"

#include <CLI/CLI.hpp>
#include <nlohmann/json_fwd.hpp>

#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace voxcone {

/// CLI11 check: the value must not be empty (an empty --method or -o would otherwise mean
/// "not given" and silently fall back to a default).
const CLI::Validator& nonEmpty();
/// CLI11 check: a finite number above zero (CLI::PositiveNumber printed DBL_MAX's 309 digits).
const CLI::Validator& positiveNumber();

/// A seed: a decimal integer in [0, 2^64 - 1]; anything else (a sign, a fraction, more than 64
/// bits) is a SettingsError naming `option`, never clamped.
uint64_t parseSeed(const std::string& option, const std::string& text);

/// `-D NAME=VALUE` options as Mitsuba scene parameters (scene/mitsuba.h); a value without '=',
/// an empty or malformed name, or a name given twice is a SettingsError.
std::map<std::string, std::string> parseDefines(const std::vector<std::string>& defines);
/// Add the repeatable `-D,--define NAME=VALUE` option to a command that reads a scene; each
/// -D takes exactly one value, so the scene file after it stays the positional argument.
void addDefineOption(CLI::App& cmd, std::vector<std::string>& defines);



/// A study's renders with `jobsInFlight` and `threadsPerJob`, here (runStudyRenders).
nlohmann::json runStudyBatch(const nlohmann::json& manifest, const std::string& outDir, int jobsInFlight,
                             int threadsPerJob);

/// Add --slurm, --partition, --time and --shards to a study command.
void addSchedulerOptions(CLI::App& cmd, StudyScheduler& scheduler);

/// Run a chart script (python3-matplotlib) on STUDY.json writing OUT_STEM.{png,svg}; prints
/// what it says. Throws Error with its first line when it fails.
void runChartScript(const std::string& script, const std::string& studyJson, const std::string& outStem);

/// The process's command line as main received it (sidecars record it); setCommandLine is
/// called once, from main.
void setCommandLine(int argc, char** argv);
const std::vector<std::string>& commandLine();

/// The folder holding voxcone's tools/ and data/ (chart scripts, scenes, fetched models), found
/// relative to the running executable so that a build tree and an installed copy both work:
/// $VOXCONE_DATA_DIR if set, else <bin>/../share/voxcone (cmake --install; the relative path
/// CMake's install directories give), else <bin>/.. when
/// it holds tools/plot_study.py (a build folder inside the source tree). Throws SettingsError.
std::string dataRoot();
/// dataRoot() + "/" + relative.
std::string dataPath(const std::string& relative);

/// The denoiser for the auxiliary images given (Denoiser::weightsFile) read from `weightsDir`,
/// or data/models/oidn where empty, and the file it came from; missing weights are a
/// SettingsError that names the fetch script.
struct LoadedDenoiser {
  Denoiser denoiser;
  std::string weightsPath;
};
LoadedDenoiser loadDenoiser(bool albedo, bool normal, const std::string& weightsDir);

}  // namespace voxcone

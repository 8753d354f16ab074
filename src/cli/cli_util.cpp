// Helpers of the subcommands that run voxcone itself in child processes.

#include "cli_util.h"

#include "voxcone/batch/process.h"
#include "voxcone/core/error.h"
#include "voxcone/denoise/tza.h"
#include "voxcone/image/image_io.h"

#include <nlohmann/json.hpp>


#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <filesystem>
#include <fstream>

namespace voxcone {

const CLI::Validator& nonEmpty() {
  static const CLI::Validator v([](std::string& s) { return s.empty() ? std::string("must not be empty") : std::string(); },
                                "NONEMPTY");
  return v;
}

const CLI::Validator& positiveNumber() {
  static const CLI::Validator v(
      [](std::string& s) {
        char* end = nullptr;
        const double d = std::strtod(s.c_str(), &end);
        const bool ok = !s.empty() && end == s.c_str() + s.size() && std::isfinite(d) && d > 0.0;
        return ok ? std::string() : "expects a positive number, got '" + s.substr(0, 40) + "'";
      },
      "POSITIVE");
  return v;
}

std::map<std::string, std::string> parseDefines(const std::vector<std::string>& defines) {
  std::map<std::string, std::string> out;
  for (const std::string& d : defines) {
    const size_t eq = d.find('=');
    const std::string name = d.substr(0, eq);
    bool ok = eq != std::string::npos && !name.empty();
    for (char c : name) ok = ok && (std::isalnum(static_cast<unsigned char>(c)) || c == '_');
    if (!ok) throw SettingsError("-D expects NAME=VALUE (NAME of letters, digits and _), got '" + d + "'");
    if (!out.emplace(name, d.substr(eq + 1)).second) throw SettingsError("-D " + name + " given twice");
  }
  return out;
}

void addDefineOption(CLI::App& cmd, std::vector<std::string>& defines) {
  cmd.add_option("-D,--define", defines,
                 "Mitsuba scene parameter NAME=VALUE: sets $NAME, overriding the scene's <default>; repeatable")
      ->allow_extra_args(false)
      ->default_str("none");
}

uint64_t parseSeed(const std::string& option, const std::string& text) {
  uint64_t v = 0;
  const char* end = text.data() + text.size();
  const auto [ptr, ec] = std::from_chars(text.data(), end, v);
  if (text.empty() || ec != std::errc() || ptr != end)
    throw SettingsError(option + ": expected an integer in [0, 18446744073709551615], got '" + text.substr(0, 40) + "'");
  return v;
}




void addSchedulerOptions(CLI::App& cmd, StudyScheduler& scheduler) {
  cmd.add_flag("--slurm", scheduler.slurm,
               "Run the renders as a Slurm job array (as batch --slurm), wait for it and merge what its tasks wrote");
  cmd.add_option("--partition", scheduler.cluster.partition, "--slurm: the partition to submit to");
  cmd.add_option("--time", scheduler.cluster.timeLimit, "--slurm: each task's time limit (e.g. 30:00)");
  cmd.add_option("--shards", scheduler.cluster.shards, "--slurm: array tasks")
      ->check(CLI::Range(size_t(1), size_t(1000000)))
      ->default_str("one per render");
}

nlohmann::json runStudyBatch(const nlohmann::json& manifest, const std::string& outDir, int jobsInFlight,
                             int threadsPerJob) {
  BatchSettings batch;
  batch.jobsInFlight = jobsInFlight;
  batch.threadsPerJob = threadsPerJob;
  return runStudyRenders(manifest, outDir, batch);
}

namespace {
std::vector<std::string> g_commandLine;
}  // namespace

void setCommandLine(int argc, char** argv) { g_commandLine.assign(argv, argv + argc); }
const std::vector<std::string>& commandLine() { return g_commandLine; }

std::string dataRoot() {
  namespace fs = std::filesystem;
  if (const char* env = std::getenv("VOXCONE_DATA_DIR"); env && *env) {
    if (!fs::is_directory(env)) throw SettingsError(std::string("VOXCONE_DATA_DIR is not a folder: ") + env);
    return env;
  }
  const fs::path bin = fs::path(selfExe()).parent_path();
  for (const fs::path& root : {bin / VOXCONE_DATA_FROM_BIN, bin / ".."}) {
    std::error_code ec;
    if (fs::is_regular_file(root / "tools" / "plot_study.py", ec)) return fs::weakly_canonical(root, ec).string();
  }
  throw SettingsError("cannot find voxcone's tools and data beside " + bin.string() +
                      " (neither ../share/voxcone nor the source tree); set VOXCONE_DATA_DIR");
}

std::string dataPath(const std::string& relative) { return dataRoot() + "/" + relative; }

void runChartScript(const std::string& script, const std::string& studyJson, const std::string& outStem) {
  std::string out;
  const std::string cmd = "/usr/bin/python3 " + shellQuote(script) + " " + shellQuote(studyJson) + " " +
                          shellQuote(outStem) + " 2>&1";
  if (runCapture(cmd, out) != 0) throw Error("chart script failed: " + out.substr(0, out.find('\n')));
  std::printf("%s", out.c_str());
}

LoadedDenoiser loadDenoiser(bool albedo, bool normal, const std::string& weightsDir) {
  const std::string file = Denoiser::weightsFile(albedo, normal);
  const std::string dir = weightsDir.empty() ? dataPath("data/models/oidn") : weightsDir;
  const std::string path = dir + "/" + file;
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    throw SettingsError("denoiser weights " + path + " not found (bash tools/fetch_models.sh fetches them)");
  return {Denoiser(readTza(path), albedo ? (normal ? 9 : 6) : 3), path};
}

}  // namespace voxcone

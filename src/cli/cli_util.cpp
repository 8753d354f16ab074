// Helpers of the subcommands that run voxcone itself in child processes.

#include "cli_util.h"

#include "voxcone/core/error.h"
#include "voxcone/image/image_io.h"

#include <nlohmann/json.hpp>

#include <sys/wait.h>

#include <array>
#include <charconv>
#include <cstdio>
#include <filesystem>
#include <fstream>

namespace voxcone {

const CLI::Validator& nonEmpty() {
  static const CLI::Validator v([](std::string& s) { return s.empty() ? std::string("must not be empty") : std::string(); },
                                "NONEMPTY");
  return v;
}

uint64_t parseSeed(const std::string& option, const std::string& text) {
  uint64_t v = 0;
  const char* end = text.data() + text.size();
  const auto [ptr, ec] = std::from_chars(text.data(), end, v);
  if (text.empty() || ec != std::errc() || ptr != end)
    throw SettingsError(option + ": expected an integer in [0, 18446744073709551615], got '" + text.substr(0, 40) + "'");
  return v;
}

std::string shellQuote(const std::string& s) {
  std::string r = "'";
  for (char c : s) r += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return r + "'";
}

int runCapture(const std::string& cmd, std::string& out) {
  FILE* p = ::popen(cmd.c_str(), "r");
  if (!p) throw Error("cannot run: " + cmd);
  std::array<char, 4096> buf;
  size_t n;
  while ((n = std::fread(buf.data(), 1, buf.size(), p)) > 0) out.append(buf.data(), n);
  const int status = ::pclose(p);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string selfExe() {
  std::error_code ec;
  const auto p = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (ec) throw Error("cannot locate the voxcone executable");
  return p.string();
}

nlohmann::json runStudyBatch(const nlohmann::json& manifest, const std::string& outDir, int jobsInFlight,
                             int threadsPerJob) {
  std::filesystem::create_directories(outDir);
  const std::string manifestPath = outDir + "/manifest.json";
  writeJsonAtomic(manifestPath, manifest);
  std::string out;
  const std::string cmd = shellQuote(selfExe()) + " batch " + shellQuote(manifestPath) + " --skip-existing -q -o " +
                          shellQuote(outDir + "/runs") + " -j " + std::to_string(jobsInFlight) + " -t " +
                          std::to_string(threadsPerJob) + " 2>&1";
  const int code = runCapture(cmd, out);
  if (code != 0 && code != 1) throw Error("batch failed: " + out.substr(0, out.find('\n')));
  std::ifstream f(outDir + "/runs/results.json");
  if (!f) throw Error("batch wrote no " + outDir + "/runs/results.json");
  return nlohmann::json::parse(f);
}

void runChartScript(const std::string& script, const std::string& studyJson, const std::string& outStem) {
  std::string out;
  const std::string cmd = "/usr/bin/python3 " + shellQuote(script) + " " + shellQuote(studyJson) + " " +
                          shellQuote(outStem) + " 2>&1";
  if (runCapture(cmd, out) != 0) throw Error("chart script failed: " + out.substr(0, out.find('\n')));
  std::printf("%s", out.c_str());
}

}  // namespace voxcone

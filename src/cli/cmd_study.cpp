// `voxcone study memory SCENE --levels 6..11`: voxelize at every level in a child process (so
// that each row's peak RSS is its own), collect one row per level into CSV and JSON, and draw
// the chart with tools/plot_memory.py.

#include "cli_util.h"
#include "commands.h"
#include "voxcone/core/error.h"
#include "voxcone/image/image_io.h"

#include <nlohmann/json.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>

namespace voxcone {

namespace {

struct StudyOptions {
  std::string scenePath;
  std::string levels = "6..11";
  std::string outDir = "out/study-memory";
  uint64_t photons = 1000000;
  int threads = 0;
  bool noChart = false;
  std::string plotScript = std::string(VOXCONE_TOOLS_DIR) + "/plot_memory.py";
};

void runStudyMemory(const StudyOptions& o) {
  static const std::regex re("^([0-9]{1,2})\\.\\.([0-9]{1,2})$");
  std::smatch m;
  if (!std::regex_match(o.levels, m, re)) throw SettingsError("--levels expects FIRST..LAST (e.g. 6..11), got '" + o.levels + "'");
  const int first = std::stoi(m[1]), last = std::stoi(m[2]);
  if (first < 1 || last > 13 || first > last) throw SettingsError("--levels must satisfy 1 <= FIRST <= LAST <= 13");
  if (!std::filesystem::exists(o.scenePath)) throw SettingsError("scene file not found: " + o.scenePath);
  std::filesystem::create_directories(o.outDir);

  nlohmann::json rows = nlohmann::json::array();
  for (int level = first; level <= last; ++level) {
    const std::string cmd = shellQuote(selfExe()) + " voxelize " + shellQuote(o.scenePath) + " --json -q --level " +
                            std::to_string(level) + " --photons " + std::to_string(o.photons) + " -t " +
                            std::to_string(o.threads) + " 2>&1";
    std::fprintf(stderr, "study memory: level %d ...\n", level);
    std::string out;
    const int code = runCapture(cmd, out);
    nlohmann::json row = {{"level", level}};
    nlohmann::json j;
    if (code == 0) {
      try {
        j = nlohmann::json::parse(out);
      } catch (const nlohmann::json::parse_error&) {
        j = nullptr;
      }
    }
    if (j.is_null() || code != 0) {
      // A failed level (e.g. out of memory) is recorded and the study goes on.
      row["error"] = out.empty() ? "exit status " + std::to_string(code) : out.substr(0, out.find('\n'));
      rows.push_back(row);
      continue;
    }
    std::map<std::string, uint64_t> bytesByGrid;
    uint64_t finestActive = 0;
    for (const auto& g : j["grids"]) {
      bytesByGrid[g["grid"].get<std::string>()] += g["bytes"].get<uint64_t>();
      if (g["grid"] == "topology" && g["level"] == level) finestActive = g["active_voxels"].get<uint64_t>();
    }
    row["voxel_size"] = j["voxel_size"];
    row["active_voxels"] = finestActive;
    row["bytes"] = bytesByGrid;
    row["total_bytes"] = j["total_bytes"];
    row["voxelize_seconds"] = j["timings"]["voxelize_seconds"];
    row["inject_seconds"] = j["timings"]["inject_seconds"];
    row["mip_seconds"] = j["timings"]["mip_seconds"];
    row["photon_seconds"] = j["timings"]["photon_seconds"];
    row["peak_rss_bytes"] = j["peak_rss_bytes"];
    rows.push_back(row);
  }

  const nlohmann::json study = {{"study", "memory"}, {"scene", o.scenePath}, {"photons", o.photons}, {"rows", rows}};
  const std::string jsonPath = o.outDir + "/memory.json", csvPath = o.outDir + "/memory.csv";
  writeJsonAtomic(jsonPath, study);
  writeFileAtomic(csvPath, [&](const std::string& tmp) {
    std::ofstream f(tmp);
    f << "level,voxel_size,active_voxels,total_mb,topology_mb,opacity_mb,normal_mb,albedo_mb,radiance_mb,"
         "voxelize_seconds,inject_seconds,mip_seconds,peak_rss_mb,error\n";
    auto mb = [](const nlohmann::json& v) { return v.is_null() ? 0.0 : v.get<double>() / 1e6; };
    for (const auto& r : rows) {
      const nlohmann::json b = r.value("bytes", nlohmann::json::object());
      f << r["level"] << "," << r.value("voxel_size", 0.0) << "," << r.value("active_voxels", 0) << ","
        << mb(r.value("total_bytes", nlohmann::json())) << "," << mb(b.value("topology", nlohmann::json())) << ","
        << mb(b.value("opacity", nlohmann::json())) << "," << mb(b.value("normal", nlohmann::json())) << ","
        << mb(b.value("albedo", nlohmann::json())) << "," << mb(b.value("radiance", nlohmann::json())) << ","
        << r.value("voxelize_seconds", 0.0) << "," << r.value("inject_seconds", 0.0) << "," << r.value("mip_seconds", 0.0)
        << "," << mb(r.value("peak_rss_bytes", nlohmann::json())) << "," << r.value("error", "") << "\n";
    }
    if (!f) throw Error("cannot write " + tmp);
  });
  std::printf("%5s %10s %12s %10s %10s %10s %10s\n", "level", "voxel", "active", "total MB", "voxelize s", "inject s",
              "peak MB");
  for (const auto& r : rows) {
    if (r.contains("error")) {
      std::printf("%5d failed: %s\n", r["level"].get<int>(), r["error"].get<std::string>().c_str());
      continue;
    }
    std::printf("%5d %10.4g %12llu %10.2f %10.3f %10.3f %10.1f\n", r["level"].get<int>(), r["voxel_size"].get<double>(),
                (unsigned long long)r["active_voxels"].get<uint64_t>(), r["total_bytes"].get<double>() / 1e6,
                r["voxelize_seconds"].get<double>(), r["inject_seconds"].get<double>(),
                r["peak_rss_bytes"].get<double>() / 1e6);
  }
  std::printf("wrote %s, %s\n", csvPath.c_str(), jsonPath.c_str());
  if (o.noChart) return;
  std::string out;
  const std::string cmd = "/usr/bin/python3 " + shellQuote(o.plotScript) + " " + shellQuote(jsonPath) + " " +
                          shellQuote(o.outDir + "/memory") + " 2>&1";
  if (runCapture(cmd, out) != 0) throw Error("chart script failed: " + out.substr(0, out.find('\n')));
  std::printf("%s", out.c_str());
}

}  // namespace

void addStudyCommand(CLI::App& app) {
  CLI::App* study = app.add_subcommand("study", "Studies: one command runs the renders and draws the charts");
  study->require_subcommand(1);
  auto o = std::make_shared<StudyOptions>();
  CLI::App* mem = study->add_subcommand("memory", "Voxel memory and time against level (CSV, JSON, PNG and SVG chart)");
  mem->add_option("scene", o->scenePath, "Scene file (JSON)")->required();
  mem->add_option("--levels", o->levels, "Levels FIRST..LAST (default 6..11)");
  mem->add_option("-o,--output", o->outDir, "Output folder (default out/study-memory)");
  mem->add_option("--photons", o->photons, "Photons per level");
  mem->add_option("-t,--threads", o->threads, "Threads per level (0 = all)")->check(CLI::Range(0, 4096));
  mem->add_option("--plot-script", o->plotScript, "Chart script (python3-matplotlib)");
  mem->add_flag("--no-chart", o->noChart, "Write CSV and JSON only");
  mem->callback([o] { runStudyMemory(*o); });
}

}  // namespace voxcone

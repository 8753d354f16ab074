// `voxcone study memory SCENE --levels 6..12`: voxelize at every level in a child process (so
// that each row's peak RSS is its own), collect one row per level into CSV and JSON, and draw
// the chart with tools/plot_memory.py. A level the memory budget refuses is a row with its
// error, and the study goes on.

#include "cli_util.h"
#include "commands.h"
#include "voxcone/core/error.h"
#include "voxcone/core/file_io.h"
#include "voxcone/image/image_io.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>

namespace voxcone {

namespace fs = std::filesystem;

namespace {

struct StudyOptions {
  std::string scenePath;
  std::string levels = "6..12";
  std::string outDir = "out/study-memory";
  uint64_t photons = 0;        // 0: the scene's (what voxelize and render use)
  double memoryBudgetMb = -1;  // -1: voxelize's default (the available memory)
  int threads = 0;
  bool noChart = false;
  std::string plotScript;  // empty: dataPath("tools/plot_memory.py")
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
    std::string cmd = "exec " + shellQuote(selfExe()) + " voxelize " + shellQuote(o.scenePath) + " --json -q --level " +
                      std::to_string(level) + " -t " + std::to_string(o.threads);
    if (o.photons > 0) cmd += " --photons " + std::to_string(o.photons);
    if (o.memoryBudgetMb >= 0.0) cmd += " --memory-budget-mb " + std::to_string(o.memoryBudgetMb);
    cmd += " 2>&1";
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
    // What the target counts: photons, voxelize, inject and mips.
    row["prepare_seconds"] = j["timings"]["photon_seconds"].get<double>() + j["timings"]["voxelize_seconds"].get<double>() +
                             j["timings"]["inject_seconds"].get<double>() + j["timings"]["mip_seconds"].get<double>();
    row["photons_stored"] = j["photons"]["stored_global"];
    row["peak_rss_bytes"] = j["peak_rss_bytes"];
    row["peak_rss_bytes_after"] = j["peak_rss_bytes_after"];
    row["estimate"] = j["estimate"];
    rows.push_back(row);
  }

  const nlohmann::json study = {{"study", "memory"},
                                 {"scene", o.scenePath},
                                 {"photons", o.photons > 0 ? nlohmann::json(o.photons) : nlohmann::json("scene")},
                                 {"rows", rows}};
  const std::string jsonPath = o.outDir + "/memory.json", csvPath = o.outDir + "/memory.csv";
  writeJsonAtomic(jsonPath, study);
  writeFileAtomic(csvPath, [&](const std::string& tmp) {
    std::ofstream f(tmp);
    static const char* const grids[] = {"topology", "opacity", "normal", "axes", "diffuse", "radiance", "radiance_back",
                                        "cone_table"};
    f << "level,voxel_size,active_voxels,total_mb";
    for (const char* g : grids) f << "," << g << "_mb";
    f << ",estimate_mb,estimate_peak_mb,photon_seconds,voxelize_seconds,inject_seconds,mip_seconds,prepare_seconds,"
         "peak_rss_mb,error\n";
    auto mb = [](const nlohmann::json& v) { return v.is_null() ? 0.0 : v.get<double>() / 1e6; };
    for (const auto& r : rows) {
      const nlohmann::json b = r.value("bytes", nlohmann::json::object());
      const nlohmann::json e = r.value("estimate", nlohmann::json::object());
      f << r["level"] << "," << r.value("voxel_size", 0.0) << "," << r.value("active_voxels", 0) << ","
        << mb(r.value("total_bytes", nlohmann::json()));
      for (const char* g : grids) f << "," << mb(b.value(g, nlohmann::json()));
      f << "," << mb(e.value("field_bytes", nlohmann::json())) << "," << mb(e.value("peak_bytes", nlohmann::json())) << ","
        << r.value("photon_seconds", 0.0) << "," << r.value("voxelize_seconds", 0.0) << "," << r.value("inject_seconds", 0.0)
        << "," << r.value("mip_seconds", 0.0) << "," << r.value("prepare_seconds", 0.0) << ","
        << mb(r.value("peak_rss_bytes", nlohmann::json())) << ",\"" << r.value("error", "") << "\"\n";
    }
    if (!f) throw Error("cannot write " + tmp);
  });
  std::printf("%5s %10s %12s %10s %11s %10s %10s %10s %9s %10s\n", "level", "voxel", "active", "total MB", "estimate MB",
              "voxelize s", "inject s", "mips s", "prepare s", "peak MB");
  for (const auto& r : rows) {
    if (r.contains("error")) {
      std::printf("%5d failed: %s\n", r["level"].get<int>(), r["error"].get<std::string>().c_str());
      continue;
    }
    std::printf("%5d %10.4g %12llu %10.2f %11.2f %10.3f %10.3f %10.3f %9.3f %10.1f\n", r["level"].get<int>(),
                r["voxel_size"].get<double>(), (unsigned long long)r["active_voxels"].get<uint64_t>(),
                r["total_bytes"].get<double>() / 1e6, r["estimate"]["field_bytes"].get<double>() / 1e6,
                r["voxelize_seconds"].get<double>(), r["inject_seconds"].get<double>(), r["mip_seconds"].get<double>(),
                r["prepare_seconds"].get<double>(), r["peak_rss_bytes"].get<double>() / 1e6);
  }
  std::printf("wrote %s, %s\n", csvPath.c_str(), jsonPath.c_str());
  if (!o.noChart) runChartScript(o.plotScript.empty() ? dataPath("tools/plot_memory.py") : o.plotScript, jsonPath, o.outDir + "/memory");
}

/// A study that is a batch of renders against a reference: speed-accuracy, photons or levels.
struct SweepOptions {
  std::string kind;
  std::string scenePath;
  std::string referencePath;
  std::string outDir;
  std::string resolution;
  int jobsInFlight = 1;
  int threads = 0;
  bool quick = false;
  bool noChart = false;
  std::vector<int64_t> photons;  ///< levels: photon counts, a second axis (default: the scene's)
  StudyScheduler scheduler;
  std::string plotScript;  // empty: dataPath("tools/plot_study.py")
};

void runSweepStudy(const SweepOptions& given) {
  if (!fs::exists(given.scenePath)) throw SettingsError("scene file not found: " + given.scenePath);
  if (!fs::exists(given.referencePath)) throw SettingsError("reference image not found: " + given.referencePath);
  // Every job renders at the reference's size: --res defaults to it, and another is an error
  // before any job runs (rendered at 256x256 against a 64x64 reference, every job's metrics
  // failed after the whole study had run).
  SweepOptions o = given;
  const Image reference = readImage(o.referencePath);
  const std::string size = std::to_string(reference.width) + "x" + std::to_string(reference.height);
  if (o.resolution.empty()) o.resolution = size;
  else if (o.resolution != size)
    throw SettingsError("--res " + o.resolution + " differs from the reference's " + size + " (" + o.referencePath +
                        "): the metrics compare images of one size");
  // The renders are a batch (resumable: finished jobs are kept); failed jobs are left out.
  if (!o.photons.empty() && o.kind != "levels") throw SettingsError("--photons is an axis of the levels study only");
  SweepSettings sweep;
  sweep.kind = o.kind;
  sweep.scenePath = fs::absolute(o.scenePath).string();
  sweep.referencePath = fs::absolute(o.referencePath).string();
  sweep.resolution = o.resolution;
  sweep.quick = o.quick;
  sweep.photons = o.photons;
  // The denoised fronts where the denoiser's weights are fetched (else a note: they are left out).
  std::error_code ec;
  sweep.denoise = o.kind == "speed-accuracy" && fs::is_regular_file(dataPath("data/models/oidn/rt_hdr_alb_nrm.tza"), ec);
  if (o.kind == "speed-accuracy" && !sweep.denoise)
    std::fprintf(stderr, "study: no denoiser weights (bash tools/fetch_models.sh): path+denoise and voxcone+denoise left out\n");
  BatchSettings batch;
  batch.jobsInFlight = o.jobsInFlight;
  batch.threadsPerJob = o.threads;
  const nlohmann::json results = runStudyRenders(sweepManifest(sweep), o.outDir, batch, o.scheduler);

  const nlohmann::json table = sweepTable(results["rows"]);
  const nlohmann::json& rows = table["rows"];
  const nlohmann::json& compare = table["comparisons"];
  const nlohmann::json study = {{"study", o.kind}, {"scene", o.scenePath}, {"reference", o.referencePath},
                                {"rows", rows}, {"comparisons", compare}};
  const std::string stem = o.outDir + "/" + o.kind;
  writeJsonAtomic(stem + ".json", study);
  writeSweepCsv(rows, stem + ".csv");
  if (o.kind == "speed-accuracy") {
  // A denoised method against denoised path, the others against path.
  std::printf("%-15s %-48s %9s %10s %8s %10s %10s\n", "method", "front point", "time s", "relMSE", "PSNR",
              "path relMSE", "path s");
  std::printf("%-15s %-48s %9s %10s %8s %10s %10s\n", "", "", "", "", "", "same time", "same error");
  for (const nlohmann::json& c : compare) {
    auto show = [](const nlohmann::json& v, const char* fmt) {
      char b[32];
      if (v.is_null()) return std::string("-");
      std::snprintf(b, sizeof b, fmt, v.get<double>());
      return std::string(b);
    };
    std::printf("%-15s %-48s %9.2f %10.5f %8s %10s %10s\n", c["method"].get<std::string>().c_str(),
                c["name"].get<std::string>().substr(0, 48).c_str(), c["seconds"].get<double>(), c["relmse"].get<double>(),
                show(c["psnr_srgb8"], "%.2f").c_str(), show(c["path_relmse_at_equal_time"], "%.5f").c_str(),
                show(c["path_seconds_at_equal_relmse"], "%.2f").c_str());
  }
  for (const nlohmann::json& c : compare) {
    if (c["method"] != "voxcone-auto") continue;
    const nlohmann::json& f = c["voxcone_front_relmse_at_equal_time"];
    std::printf("voxcone-auto, target %s: predicted relMSE %.5f, measured %.5f in %.2f s; voxcone's front at that "
                "time: %s\n",
                c["target"].get<std::string>().c_str(), c["predicted_relmse"].get<double>(), c["relmse"].get<double>(),
                c["seconds"].get<double>(),
                f.is_null() ? "outside the front's time range"
                            : ("relMSE " + std::to_string(f.get<double>()) + " (" +
                               std::to_string(c["relmse"].get<double>() / f.get<double>()) + "x)").c_str());
  }
  } else {
    std::printf("%-8s %8s %6s %9s %10s %10s %8s %10s\n", "method", "photons", "level", "time s", "relMSE", "MSE",
                "PSNR", "field MB");
    for (const nlohmann::json& r : rows) {
      auto num = [](const nlohmann::json& v) { return v.is_null() ? std::string("-") : v.dump(); };
      std::printf("%-8s %8s %6s %9.2f %10.5f %10.3g %8.2f %10.2f\n", r["method"].get<std::string>().c_str(),
                  num(r["photons"]).c_str(), num(r["level"]).c_str(), r["seconds"].get<double>(),
                  r["relmse"].get<double>(), r["mse"].get<double>(),
                  r["psnr_srgb8"].is_null() ? 0.0 : r["psnr_srgb8"].get<double>(), r["field_bytes"].get<double>() / 1e6);
    }
  }
  std::printf("wrote %s.csv, %s.json\n", stem.c_str(), stem.c_str());
  if (!o.noChart) runChartScript(o.plotScript.empty() ? dataPath("tools/plot_study.py") : o.plotScript, stem + ".json", stem);
}

}  // namespace

void addStudyCommand(CLI::App& app) {
  CLI::App* study = app.add_subcommand("study", "Studies: one command runs the renders and draws the charts");
  study->require_subcommand(1);
  auto o = std::make_shared<StudyOptions>();
  CLI::App* mem = study->add_subcommand("memory", "Voxel memory and time against level (CSV, JSON, PNG and SVG chart)");
  mem->add_option("scene", o->scenePath, "Scene file (JSON)")->required();
  mem->add_option("--levels", o->levels, "Levels FIRST..LAST");
  mem->add_option("-o,--output", o->outDir, "Output folder");
  mem->add_option("--photons", o->photons, "Photons per level (as voxelize and render use)")
      ->default_str("the scene's");
  mem->add_option("--memory-budget-mb", o->memoryBudgetMb,
                  "Budget per level, MB (0: none; default: voxelize's, the available memory): a level over it is "
                  "refused and recorded")
      ->check(CLI::Range(0.0, 1e12))
      ->default_str("the machine's available memory");
  mem->add_option("-t,--threads", o->threads, "Threads per level (0 = all)")->check(CLI::Range(0, 4096));
  mem->add_option("--plot-script", o->plotScript, "Chart script (python3-matplotlib)")
      ->default_str("<data>/tools/plot_memory.py");
  mem->add_flag("--no-chart", o->noChart, "Write CSV and JSON only");
  mem->callback([o] { runStudyMemory(*o); });

  const std::pair<const char*, const char*> sweeps[] = {
      {"speed-accuracy", "Every method over its settings: time against error, Pareto fronts, equal-time/error table"},
      {"photons", "Error (MSE, PSNR) against photon count for pm and voxcone"},
      {"levels", "voxcone's time, memory and error against voxel level"}};
  for (const auto& [kind, help] : sweeps) {
    auto so = std::make_shared<SweepOptions>();
    so->kind = kind;
    so->outDir = std::string("out/study-") + kind;
    CLI::App* cmd = study->add_subcommand(kind, help);
    cmd->add_option("scene", so->scenePath, "Scene file (JSON)")->required();
    cmd->add_option("--reference", so->referencePath, "Converged reference image (EXR)")->required();
    cmd->add_option("-o,--output", so->outDir, "Output folder");
    cmd->add_option("--res", so->resolution, "Resolution WIDTHxHEIGHT (the reference's)")
      ->default_str("the reference's");
    cmd->add_option("-j,--jobs", so->jobsInFlight, "Renders in flight")->check(CLI::Range(1, 1024));
    cmd->add_option("-t,--threads", so->threads, "Threads per render (0 = all)")->check(CLI::Range(0, 4096));
    cmd->add_flag("--quick", so->quick, "A few cheap settings (for tests)");
    cmd->add_option("--plot-script", so->plotScript, "Chart script (python3-matplotlib)")
      ->default_str("<data>/tools/plot_study.py");
    cmd->add_flag("--no-chart", so->noChart, "Write CSV and JSON only");
    if (std::string(kind) == "levels")
      cmd->add_option("--photons", so->photons, "Photon counts, a second axis (levels x photons; default: the scene's)")
          ->check(CLI::Range(int64_t(1), int64_t(1) << 40))
          ->delimiter(',')
      ->default_str("the scene's");
    addSchedulerOptions(*cmd, so->scheduler);
    cmd->callback([so] { runSweepStudy(*so); });
  }
  addStructureStudies(*study);
}

}  // namespace voxcone

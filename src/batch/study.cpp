// Sweep studies (study.h): manifests, their renders here or on Slurm, Pareto fronts and tables.

#include "voxcone/batch/study.h"

#include "voxcone/core/error.h"
#include "voxcone/core/file_io.h"
#include "voxcone/image/image_io.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>

namespace voxcone {

namespace fs = std::filesystem;

/// The study's renders as a batch manifest. speed-accuracy: every method over its settings (path
/// spp; pm photons; voxcone level x photons x cones x spp); photons: pm and voxcone over photon
/// counts from the 1000-5000 of the study we compare with up to 1M; levels: voxcone over voxel
/// levels.
nlohmann::json sweepManifest(const SweepSettings& o) {
  nlohmann::json defaults = {{"scene", fs::absolute(o.scenePath).string()}};
  if (!o.resolution.empty()) defaults["res"] = o.resolution;
  nlohmann::json grid;
  if (o.kind == "photons") {
    const nlohmann::json photons = o.quick ? nlohmann::json{1000, 4000}
                                           : nlohmann::json{1000, 2000, 5000, 10000, 100000, 1000000};
    const nlohmann::json base = o.quick ? nlohmann::json{{"level", 4}} : nlohmann::json::object();
    nlohmann::json vc = base, pm = nlohmann::json::object();
    vc["photons"] = photons;
    pm["photons"] = photons;
    grid = {{{"method", "pm"}, {"spp", o.quick ? 2 : 16}, {"options", pm}},
            {{"method", "voxcone"}, {"spp", o.quick ? 2 : 16}, {"options", vc}}};
  } else if (o.kind == "levels") {
    nlohmann::json options = {{"level", o.quick ? nlohmann::json{3, 4, 5} : nlohmann::json{5, 6, 7, 8, 9}}};
    if (!o.photons.empty()) options["photons"] = o.photons;  // levels x photons
    else if (o.quick) options["photons"] = 4000;
    grid = {{{"method", "voxcone"}, {"spp", o.quick ? 1 : 16}, {"options", options}}};
  } else if (o.quick) {
    grid = {{{"method", "path"}, {"spp", {1, 4, 16}}},
            {{"method", "pm"}, {"spp", 2}, {"options", {{"photons", {2000, 8000}}}}},
            {{"method", "voxcone"}, {"spp", 2}, {"options", {{"level", {4, 5}}, {"photons", 4000}, {"cones", {6, 16}}}}},
            {{"method", "voxcone"}, {"target_error", 0.05}}};
    if (o.denoise) {
      grid.push_back({{"method", "path"}, {"spp", {1, 4}}, {"denoise", true}});
      grid.push_back({{"method", "voxcone"}, {"spp", 2}, {"options", {{"level", 4}, {"photons", 4000}}}, {"denoise", true}});
    }
  } else {
    grid = {{{"method", "path"}, {"spp", {4, 8, 16, 32, 64, 256, 1024}}},
            {{"method", "pm"}, {"spp", 16}, {"options", {{"photons", {100000, 300000, 1000000}}}}},
            // voxcone's defaults over spp, then where its indirect light is gathered: one pixel
            // per 1x1, 2x2 or 4x4 block, 1, 4 or 16 gathers there, at 4 and 16 spp; levels 5-7.
            {{"method", "voxcone"}, {"spp", {2, 4, 8, 16, 64}}},
            {{"method", "voxcone"}, {"spp", {4, 16}},
             {"options", {{"gather_spacing", {1, 2, 4}}, {"gathers", {1, 4, 16}}}}},
            {{"method", "voxcone"}, {"spp", 16}, {"options", {{"level", {5, 7}}}}},
            // Its most accurate: every pixel gathering 16 times with 16 cones, 64 spp.
            {{"method", "voxcone"}, {"spp", 64},
             {"options", {{"gather_spacing", 1}, {"gathers", 16}, {"filter", 8}, {"cones", {6, 16}}}}},
            // render --target-error / --time-budget: where its choices land against the fronts.
            {{"method", "voxcone"}, {"target_error", {0.002, 0.001, 0.0008}}},
            {{"method", "voxcone"}, {"time_budget", {0.5, 1, 2, 5}}}};
    // The fair race (docs/method.md: the fair race): both denoised, over spp; voxcone also with the
    // photons it takes without the denoiser (four times its denoised default).
    if (o.denoise) {
      grid.push_back({{"method", "path"}, {"spp", {1, 2, 4, 8, 16, 64}}, {"denoise", true}});
      grid.push_back({{"method", "voxcone"}, {"spp", {1, 2, 4, 8, 16}}, {"denoise", true}});
      grid.push_back({{"method", "voxcone"}, {"spp", {2, 4, 8}}, {"options", {{"photon_target", 200000}}}, {"denoise", true}});
    }
  }
  return {{"reference", fs::absolute(o.referencePath).string()}, {"defaults", defaults}, {"grid", grid}};
}


nlohmann::json runStudyRenders(const nlohmann::json& manifest, const std::string& outDir, const BatchSettings& batch,
                               const StudyScheduler& scheduler) {
  fs::create_directories(outDir);
  const std::string manifestPath = outDir + "/manifest.json";
  writeJsonAtomic(manifestPath, manifest);
  const Manifest m = loadManifest(manifestPath, outDir + "/runs");
  const std::string stem = (m.outDir / "results").string();
  const nlohmann::json info = {{"manifest", m.path}};
  if (!scheduler.slurm) {
    // Resumable: the renders a previous run finished are kept. The batch's "[i/N] ..." lines
    // are the study's progress.
    BatchSettings b = batch;
    b.skipExisting = true;
    const BatchReport r = runJobs(m.jobs, m.outDir, stem, b, info);
    if (r.interrupted) throw CancelledError("the study's renders were interrupted; run it again to resume");
    return {{"rows", r.rows}};
  }
  const auto [id, script] = submitSlurm(scheduler.cluster, batch, m.path, fs::absolute(m.outDir), m.jobs.size());
  std::fprintf(stderr, "study: submitted job array %s (%zu tasks, script %s); waiting\n", id.c_str(),
               slurmShards(scheduler.cluster, m.jobs.size()), script.c_str());
  waitForSlurmJob(id);
  const MergeReport r = mergeShards(m.jobs, m.outDir);
  writeTables(r.rows, stem, {{"manifest", m.path}, {"merged", true}, {"slurm_job", id}});
  for (const std::string& line : r.notComplete) std::fprintf(stderr, "study: %s\n", line.c_str());
  return {{"rows", r.rows}};
}

/// Indices of the Pareto front of `pts` (time, error), both minimized: the points no other point
/// beats on both; sorted by time.
std::vector<size_t> paretoFront(const std::vector<std::pair<double, double>>& pts) {
  std::vector<size_t> order(pts.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    return pts[a].first != pts[b].first ? pts[a].first < pts[b].first : pts[a].second < pts[b].second;
  });
  std::vector<size_t> front;
  double best = std::numeric_limits<double>::infinity();
  for (size_t i : order)
    if (pts[i].second < best) {
      front.push_back(i);
      best = pts[i].second;
    }
  return front;
}

/// y at x on a front (sorted by x), log-log linear between its points; NaN outside it.
double onFront(const std::vector<std::pair<double, double>>& front, double x) {
  for (size_t i = 0; i + 1 < front.size(); ++i) {
    const auto& [x0, y0] = front[i];
    const auto& [x1, y1] = front[i + 1];
    if (x0 <= x && x <= x1) {
      const double u = x1 > x0 ? (std::log(x) - std::log(x0)) / (std::log(x1) - std::log(x0)) : 0.0;
      return std::exp(std::log(y0) + u * (std::log(y1) - std::log(y0)));
    }
  }
  return std::numeric_limits<double>::quiet_NaN();
}

nlohmann::json sweepTable(const nlohmann::json& batchRows) {
  const nlohmann::json results = {{"rows", batchRows}};
  // One row per successful render; the Pareto front of each method in (time, relMSE).
  nlohmann::json rows = nlohmann::json::array();
  std::map<std::string, std::vector<size_t>> byMethod;
  for (const nlohmann::json& r : results["rows"]) {
    if (r["status"] != "ok" && r["status"] != "existing") continue;
    if (!r.contains("metrics") || !r["metrics"].contains("relmse")) continue;
    // Renders that chose their own settings (--target-error / --time-budget) are a series of
    // their own.
    const bool chosen = r.contains("target_error") || r.contains("time_budget");
    const std::string method =
        r["method"].get<std::string>() + (r.value("denoise", false) ? "+denoise" : "") + (chosen ? "-auto" : "");
    byMethod[method].push_back(rows.size());
    const nlohmann::json st = r.value("integrator", nlohmann::json::object());
    rows.push_back({{"name", r["name"]}, {"method", method}, {"spp", r.value("resolved_spp", r.value("spp", 0))}, {"options", r["options"]},
                    {"photons", st.value("photons", nlohmann::json())}, {"level", st.value("level", nlohmann::json())},
                    {"seconds", r["timings"]["total_seconds"]}, {"relmse", r["metrics"]["relmse"]},
                    {"psnr_srgb8", r["metrics"]["psnr_srgb8"]}, {"mse", r["metrics"]["mse"]},
                    {"peak_rss_bytes", r["peak_rss_bytes"]},
                    {"field_bytes", r.value("field_bytes", nlohmann::json(0))}, {"pareto", false}});
    if (chosen) {
      rows.back()["predicted_relmse"] = r["auto"]["predicted_relmse"];
      rows.back()["target"] = r.contains("target_error") ? "relMSE " + r["target_error"].dump()
                                                         : r["time_budget"].dump() + " s";
    }
  }
  std::map<std::string, std::vector<std::pair<double, double>>> fronts;
  for (const auto& [method, idx] : byMethod) {
    std::vector<std::pair<double, double>> pts;
    for (size_t i : idx) pts.emplace_back(rows[i]["seconds"].get<double>(), rows[i]["relmse"].get<double>());
    for (size_t k : paretoFront(pts)) {
      rows[idx[k]]["pareto"] = true;
      fronts[method].push_back(pts[k]);
    }
  }
  // Equal-time and equal-error comparisons: each front point of pm and voxcone against path's
  // front, a denoised method's against denoised path's.
  nlohmann::json compare = nlohmann::json::array();
  // A front inverted (error -> time): fronts are sorted by time, errors falling.
  auto inverted = [](const std::vector<std::pair<double, double>>& front) {
    std::vector<std::pair<double, double>> inv;
    for (auto it = front.rbegin(); it != front.rend(); ++it) inv.emplace_back(it->second, it->first);
    return inv;
  };
  auto num = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  for (const nlohmann::json& r : rows) {
    // pm's and voxcone's front points; every render that chose its settings.
    const bool chosen = r["method"] == "voxcone-auto";
    const std::string method = r["method"].get<std::string>();
    if ((!r["pareto"].get<bool>() && !chosen) || method == "path" || method == "path+denoise") continue;
    const bool denoised = method.find("+denoise") != std::string::npos;
    const auto& pathFront = fronts[denoised ? "path+denoise" : "path"];
    const double t = r["seconds"].get<double>(), e = r["relmse"].get<double>();
    const double pathErr = onFront(pathFront, t), pathTime = onFront(inverted(pathFront), e);
    nlohmann::json c = {{"name", r["name"]}, {"method", r["method"]}, {"seconds", t}, {"relmse", e},
                        {"psnr_srgb8", r["psnr_srgb8"]},
                        {"against", denoised ? "path+denoise" : "path"},
                        {"path_relmse_at_equal_time", num(pathErr)}, {"path_seconds_at_equal_relmse", num(pathTime)},
                        {"speedup_vs_path", num(pathTime / t)}};
    if (chosen) {
      // How close the choice lands to voxcone's own front.
      const auto& vf = fronts["voxcone"];
      c["target"] = r["target"];
      c["predicted_relmse"] = r["predicted_relmse"];
      c["voxcone_front_relmse_at_equal_time"] = num(onFront(vf, t));
      c["voxcone_front_seconds_at_equal_relmse"] = num(onFront(inverted(vf), e));
    }
    compare.push_back(c);
  }
  return {{"rows", rows}, {"comparisons", compare}};
}

void writeSweepCsv(const nlohmann::json& rows, const std::string& path) {
  writeFileAtomic(path, [&](const std::string& tmp) {
    std::ofstream c(tmp);
    c << "name,method,spp,photons,level,options,seconds,relmse,mse,psnr_srgb8,peak_rss_mb,field_mb,pareto\n";
    for (const nlohmann::json& r : rows) {
      std::string opts = r["options"].dump();
      std::string quoted = "\"";
      for (char ch : opts) quoted += ch == '"' ? std::string("\"\"") : std::string(1, ch);
      auto orEmpty = [](const nlohmann::json& v) { return v.is_null() ? std::string() : v.dump(); };
      c << r["name"].get<std::string>() << "," << r["method"].get<std::string>() << "," << r["spp"] << ","
        << orEmpty(r["photons"]) << "," << orEmpty(r["level"]) << "," << quoted << "\"," << r["seconds"] << ","
        << r["relmse"] << "," << r["mse"] << "," << r["psnr_srgb8"] << ","
        << r["peak_rss_bytes"].get<double>() / 1e6 << "," << r["field_bytes"].get<double>() / 1e6 << ","
        << (r["pareto"].get<bool>() ? 1 : 0) << "\n";
    }
    if (!c) throw Error("cannot write " + tmp);
  });
}

}  // namespace voxcone

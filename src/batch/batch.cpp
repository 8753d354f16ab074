// Batches of renders (batch.h): manifests expanded into named jobs, jobs run as child `voxcone
// render` processes in parallel with TBB, results tables, shards merged, Slurm job arrays.

#include "voxcone/batch/batch.h"

#include "voxcone/batch/process.h"
#include "voxcone/core/error.h"
#include "voxcone/core/file_io.h"
#include "voxcone/core/progress.h"
#include "voxcone/core/timer.h"
#include "voxcone/image/image_io.h"
#include "voxcone/image/metrics.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>
#include <tbb/task_arena.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <mutex>
#include <regex>
#include <set>
#include <sstream>
#include <thread>

namespace voxcone {

namespace fs = std::filesystem;

namespace {

/// Keys a job (or a grid entry, or the defaults) may set.
const std::set<std::string> kJobKeys = {"name",    "scene",   "method", "spp",   "res",      "seed",
                                        "max_depth", "options", "accel",  "threads", "reference",
                                        "target_error", "time_budget", "denoise"};



void checkKeys(const nlohmann::json& obj, const std::set<std::string>& allowed, const std::string& where) {
  if (!obj.is_object()) throw SettingsError(where + ": expected an object");
  for (const auto& [key, value] : obj.items())
    if (!allowed.count(key)) throw SettingsError(where + "." + key + ": unknown key");
}

/// A path from the manifest, relative to the manifest's folder.
std::string resolvePath(const fs::path& base, const std::string& p) {
  return fs::path(p).is_absolute() ? p : (base / p).lexically_normal().string();
}

/// 64-bit FNV-1a (the name's hash: the same spec gives the same name on every machine).
uint64_t fnv1a(const std::string& s) {
  uint64_t h = 1469598103934665603ULL;
  for (unsigned char c : s) h = (h ^ c) * 1099511628211ULL;
  return h;
}

/// `v` as a file-name fragment: letters, digits, '.', '-'; anything else becomes '-'.
std::string slug(const nlohmann::json& v) {
  std::string s = v.is_string() ? v.get<std::string>() : v.dump();
  for (char& c : s)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '.' && c != '-') c = '-';
  return s;
}

}  // namespace

/// The job's deterministic output name: scene, method, spp and every option, then a hash of the
/// whole spec (resolution, seed, reference... and values a slug cannot tell apart).
std::string jobName(const nlohmann::json& spec) {
  std::string name = fs::path(spec["scene"].get<std::string>()).stem().string();
  if (spec.contains("method")) name += "_" + slug(spec["method"]);
  if (spec.contains("spp")) name += "_spp" + slug(spec["spp"]);
  if (spec.contains("accel")) name += "_" + slug(spec["accel"]);
  if (spec.contains("threads")) name += "_t" + slug(spec["threads"]);
  if (spec.contains("target_error")) name += "_target" + slug(spec["target_error"]);
  if (spec.contains("time_budget")) name += "_budget" + slug(spec["time_budget"]);
  if (spec.value("denoise", false)) name += "_denoise";
  for (const auto& [key, value] : spec["options"].items()) name += "_" + slug(key) + slug(value);
  if (name.size() > 120) name.resize(120);
  char hash[17];
  std::snprintf(hash, sizeof hash, "%08llx", static_cast<unsigned long long>(fnv1a(spec.dump()) & 0xffffffffULL));
  return name + "_" + hash;
}

namespace {

/// Fill `spec` from `src` (already key-checked), paths resolved against the manifest folder.
void applySpec(nlohmann::json& spec, const nlohmann::json& src, const fs::path& base, const std::string& where) {
  for (const auto& [key, value] : src.items()) {
    if (key == "name") continue;
    if (key == "options") {
      if (!value.is_object()) throw SettingsError(where + ".options: expected an object");
      for (const auto& [k, v] : value.items()) spec["options"][k] = v;
    } else if (key == "scene" || key == "reference") {
      if (!value.is_string()) throw SettingsError(where + "." + key + ": expected a path");
      spec[key] = resolvePath(base, value.get<std::string>());
    } else {
      spec[key] = value;
    }
  }
}

/// Check the types of a finished spec.
void validateSpec(const nlohmann::json& spec, const std::string& where) {
  if (!spec.contains("scene")) throw SettingsError(where + ": no scene (give one in the job or in defaults)");
  auto isInt = [&](const char* k) { return !spec.contains(k) || spec[k].is_number_integer(); };
  if (!isInt("spp") || !isInt("seed") || !isInt("max_depth") || !isInt("threads"))
    throw SettingsError(where + ": spp, seed, max_depth and threads must be integers");
  if (spec.contains("accel") && !spec["accel"].is_string()) throw SettingsError(where + ".accel: expected a string");
  for (const char* k : {"target_error", "time_budget"})
    if (spec.contains(k) && !(spec[k].is_number() && spec[k].get<double>() > 0.0))
      throw SettingsError(where + "." + k + ": expected a positive number");
  if (spec.contains("method") && !spec["method"].is_string()) throw SettingsError(where + ".method: expected a string");
  if (spec.contains("denoise") && !spec["denoise"].is_boolean()) throw SettingsError(where + ".denoise: expected true or false");
  if (spec.contains("res") && !spec["res"].is_string()) throw SettingsError(where + ".res: expected WIDTHxHEIGHT");
  // Before any job runs: every job's metrics would fail (they were recorded as "ok" with
  // empty metric columns).
  std::error_code ec;
  if (spec.contains("reference") && !fs::is_regular_file(spec["reference"].get<std::string>(), ec))
    throw SettingsError(where + ".reference: no such image file: " + spec["reference"].get<std::string>());
}

}  // namespace

/// The manifest's jobs, in order: "jobs" first, then each "grid" entry expanded (every array
/// value, top level or in options, is an axis; axes in key order, options' at "options", the
/// last varying fastest).
std::vector<Job> expandManifest(const nlohmann::json& m, const fs::path& base) {
  checkKeys(m, {"output_dir", "reference", "defaults", "jobs", "grid"}, "manifest");
  nlohmann::json defaults = {{"options", nlohmann::json::object()}};
  if (m.contains("reference")) applySpec(defaults, {{"reference", m["reference"]}}, base, "manifest");
  if (m.contains("defaults")) {
    checkKeys(m["defaults"], kJobKeys, "defaults");
    if (m["defaults"].contains("name")) throw SettingsError("defaults.name: a name belongs to one job");
    applySpec(defaults, m["defaults"], base, "defaults");
  }
  std::vector<Job> jobs;
  auto add = [&](const nlohmann::json& src, const std::string& where) {
    nlohmann::json spec = defaults;
    applySpec(spec, src, base, where);
    validateSpec(spec, where);
    Job job;
    job.spec = spec;
    if (src.contains("name")) {
      static const std::regex kName("^[A-Za-z0-9._-]{1,160}$");
      if (!src["name"].is_string() || !std::regex_match(src["name"].get<std::string>(), kName))
        throw SettingsError(where + ".name: letters, digits, '.', '_' and '-' only");
      job.name = src["name"].get<std::string>();
    } else {
      job.name = jobName(spec);
    }
    jobs.push_back(job);
  };
  if (m.contains("jobs")) {
    if (!m["jobs"].is_array()) throw SettingsError("jobs: expected an array");
    for (size_t i = 0; i < m["jobs"].size(); ++i) {
      const std::string where = "jobs[" + std::to_string(i) + "]";
      checkKeys(m["jobs"][i], kJobKeys, where);
      add(m["jobs"][i], where);
    }
  }
  if (m.contains("grid")) {
    const nlohmann::json grids = m["grid"].is_array() ? m["grid"] : nlohmann::json::array({m["grid"]});
    for (size_t g = 0; g < grids.size(); ++g) {
      const std::string where = "grid[" + std::to_string(g) + "]";
      checkKeys(grids[g], kJobKeys, where);
      if (grids[g].contains("name")) throw SettingsError(where + ".name: grid jobs are named from their settings");
      // Axes: (key, option key or "", values).
      struct Axis {
        std::string key, option;
        nlohmann::json values;
      };
      std::vector<Axis> axes;
      for (const auto& [key, value] : grids[g].items()) {
        if (key == "options" && value.is_object()) {
          for (const auto& [k, v] : value.items())
            if (v.is_array()) axes.push_back({key, k, v});
        } else if (value.is_array()) {
          axes.push_back({key, "", value});
        }
      }
      for (const Axis& a : axes)
        if (a.values.empty()) throw SettingsError(where + "." + a.key + (a.option.empty() ? "" : "." + a.option) + ": empty axis");
      std::vector<size_t> index(axes.size(), 0);
      while (true) {
        nlohmann::json src = grids[g];
        for (size_t a = 0; a < axes.size(); ++a) {
          if (axes[a].option.empty()) src[axes[a].key] = axes[a].values[index[a]];
          else src["options"][axes[a].option] = axes[a].values[index[a]];
        }
        add(src, where);
        size_t a = axes.size();
        while (a > 0 && ++index[a - 1] == axes[a - 1].values.size()) index[--a] = 0;
        if (a == 0) break;
      }
    }
  }
  std::set<std::string> names;
  for (const Job& j : jobs)
    if (!names.insert(j.name).second) throw SettingsError("two jobs are named " + j.name + " (the same settings twice?)");
  return jobs;
}

/// Parse "I/N" (0 <= I < N).
std::pair<size_t, size_t> parseShard(const std::string& s) {
  static const std::regex re("^([0-9]{1,6})/([0-9]{1,6})$");
  std::smatch m;
  if (!std::regex_match(s, m, re)) throw SettingsError("--shard expects I/N (e.g. 0/4), got '" + s + "'");
  const size_t i = std::stoul(m[1]), n = std::stoul(m[2]);
  if (n == 0 || i >= n) throw SettingsError("--shard I/N needs 0 <= I < N, got '" + s + "'");
  return {i, n};
}


/// Whether job `name` left a complete set in `outDir` (what --skip-existing may keep): its
/// sidecar parses, and its EXR opens with the size the sidecar records. The sidecar alone
/// trusted an EXR deleted or truncated since.
bool completeOutputs(const fs::path& outDir, const std::string& name) {
  try {
    const fs::path sidecar = outDir / (name + ".json");
    if (!fs::exists(sidecar)) return false;
    std::ifstream f(sidecar);
    const nlohmann::json meta = nlohmann::json::parse(f);
    const Image image = readImage((outDir / (name + ".exr")).string());
    return image.width == meta.at("settings").at("width").get<int>() &&
           image.height == meta.at("settings").at("height").get<int>();
  } catch (const std::exception&) {
    return false;
  }
}

namespace {

/// The voxcone a batch runs: the one it names, else this executable.
std::string executableOf(const BatchSettings& o) { return o.executable.empty() ? selfExe() : o.executable; }

/// Run `job` as a child `voxcone render` writing outDir/<name>.{exr,png,json} (given as
/// -o <name>.exr: a name may hold dots, which render would take for an unknown extension).
JobResult runJob(const Job& job, const fs::path& outDir, const BatchSettings& o) {
  const nlohmann::json& s = job.spec;
  std::string cmd;
  if (o.memoryBudgetMb > 0.0)  // the data segment and private writable mappings: the heap
    cmd += "ulimit -d " + std::to_string(static_cast<long long>(o.memoryBudgetMb * 1024.0)) + " && ";
  cmd += "exec " + shellQuote(executableOf(o)) + " render " + shellQuote(s["scene"].get<std::string>()) + " -q -o " +
         shellQuote((outDir / job.name).string() + ".exr") + " -t " +
         std::to_string(s.contains("threads") ? s["threads"].get<int64_t>() : int64_t(o.threadsPerJob)) + " --options " +
         shellQuote(s["options"].dump());
  if (s.contains("method")) cmd += " --method " + shellQuote(s["method"].get<std::string>());
  if (s.contains("spp")) cmd += " --spp " + std::to_string(s["spp"].get<int64_t>());
  if (s.contains("res")) cmd += " --res " + shellQuote(s["res"].get<std::string>());
  if (s.contains("seed")) cmd += " --seed " + std::to_string(s["seed"].get<int64_t>());
  if (s.contains("max_depth")) cmd += " --max-depth " + std::to_string(s["max_depth"].get<int64_t>());
  if (s.contains("accel")) cmd += " --accel " + shellQuote(s["accel"].get<std::string>());
  if (s.contains("target_error")) cmd += " --target-error " + s["target_error"].dump();
  if (s.contains("time_budget")) cmd += " --time-budget " + s["time_budget"].dump();
  if (s.value("denoise", false)) cmd += " --denoise";
  cmd += " 2>&1";
  std::string out;
  const int code = runCapture(cmd, out);
  JobResult r;
  if (code == 128 + SIGINT || code == 128 + SIGTERM || code == 128 + SIGKILL) {
    // Stopped by a signal (the batch passing on its own, a scheduler, a user): no outputs;
    // --skip-existing runs it again.
    r.status = "interrupted";
    r.error = std::string("stopped by ") + (code == 128 + SIGINT ? "SIGINT" : code == 128 + SIGTERM ? "SIGTERM" : "SIGKILL");
    return r;
  }
  if (code != 0) {
    r.status = "failed";
    r.error = lastLine(out);
    if (r.error.empty()) r.error = "exit status " + std::to_string(code);
    if (o.memoryBudgetMb > 0.0 && r.error.find("out of memory") != std::string::npos)
      r.error += " (memory budget " + std::to_string(static_cast<long long>(o.memoryBudgetMb)) + " MB)";
    return r;
  }
  r.status = "ok";
  return r;
}

/// Image metrics of outDir/<name>.exr against the job's reference (cached per reference path).
nlohmann::json jobMetrics(const Job& job, const fs::path& outDir, std::map<std::string, Image>& refs,
                          std::mutex& refsMutex) {
  if (!job.spec.contains("reference")) return nullptr;
  const std::string refPath = job.spec["reference"].get<std::string>();
  try {
    const Image* ref = nullptr;
    {
      std::lock_guard<std::mutex> lock(refsMutex);
      auto it = refs.find(refPath);
      if (it == refs.end()) it = refs.emplace(refPath, readImage(refPath)).first;
      ref = &it->second;
    }
    return compareImages(readImage((outDir / (job.name + ".exr")).string()), *ref).toJson();
  } catch (const Error& e) {
    return {{"error", e.what()}};
  }
}

/// A finished job's sidecar and metrics into `r`. A job whose metrics cannot be computed (its
/// image and the reference differ in size or kind, the reference is unreadable) has failed,
/// not passed.
void readOutputs(const Job& job, const fs::path& outDir, std::map<std::string, Image>& refs, std::mutex& refsMutex,
                 JobResult& r) {
  const fs::path sidecar = outDir / (job.name + ".json");
  try {
    std::ifstream f(sidecar);
    r.sidecar = nlohmann::json::parse(f);
    r.metrics = jobMetrics(job, outDir, refs, refsMutex);
    if (r.metrics.is_object() && r.metrics.contains("error")) {
      r.status = "failed";
      r.error = "metrics: " + r.metrics["error"].get<std::string>();
    }
  } catch (const std::exception& e) {
    r.status = "failed";
    r.error = "cannot read " + sidecar.string() + ": " + e.what();
  }
}

/// A CSV field, quoted when it holds a comma, a quote or a line break.
std::string csvField(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string r = "\"";
  for (char c : s) r += c == '"' ? std::string("\"\"") : std::string(1, c);
  return r + "\"";
}

/// A number from a JSON path, or "" when absent.
std::string csvNumber(const nlohmann::json& j, const nlohmann::json::json_pointer& p, double scale = 1.0) {
  if (!j.is_object() || !j.contains(p) || !j[p].is_number()) return "";
  std::ostringstream s;
  s.precision(10);
  s << j[p].get<double>() * scale;
  return s.str();
}

}  // namespace

nlohmann::json resultRow(const Job& job, const JobResult& r) {
  nlohmann::json row = {{"name", job.name}, {"status", r.status}};
  for (const auto& [k, v] : job.spec.items()) row[k] = v;
  if (!r.error.empty()) row["error"] = r.error;
  if (r.sidecar.is_object()) {
    row["timings"] = r.sidecar.value("timings", nlohmann::json::object());
    row["peak_rss_bytes"] = r.sidecar.value("peak_rss_bytes", nlohmann::json());
    const nlohmann::json st = r.sidecar.value("settings", nlohmann::json::object());
    row["width"] = st.value("width", nlohmann::json());
    row["height"] = st.value("height", nlohmann::json());
    row["resolved_method"] = r.sidecar.value("method", nlohmann::json());
    row["resolved_spp"] = st.value("spp", nlohmann::json());
    if (r.sidecar.contains("auto")) row["auto"] = r.sidecar["auto"];
    row["integrator"] = st.value("integrator", nlohmann::json::object());
    const nlohmann::json::json_pointer fieldBytes("/stats/integrator/field_bytes");
    if (r.sidecar.contains(fieldBytes)) row["field_bytes"] = r.sidecar[fieldBytes];
    row["threads_used"] = st.value("threads", nlohmann::json());
    const nlohmann::json stats = r.sidecar.value("stats", nlohmann::json::object());
    row["accel_stats"] = stats.value("accel", nlohmann::json::object());
    row["triangles"] = stats.value("scene", nlohmann::json::object()).value("triangles", nlohmann::json());
    row["outputs"] = r.sidecar.value("outputs", nlohmann::json::object());
  }
  if (!r.metrics.is_null()) row["metrics"] = r.metrics;
  return row;
}

void writeTables(const std::vector<nlohmann::json>& rows, const std::string& stem, const nlohmann::json& info) {
  nlohmann::json doc = info;
  doc["rows"] = rows;
  writeJsonAtomic(stem + ".json", doc);
  writeFileAtomic(stem + ".csv", [&](const std::string& tmp) {
    std::ofstream f(tmp);
    f << "name,scene,method,spp,width,height,seed,options,status,error,load_s,build_s,prepare_s,render_s,total_s,"
         "peak_rss_mb,field_mb,accel,accel_mb,threads,reference,relmse,mse,psnr_srgb8,ssim\n";
    using P = nlohmann::json::json_pointer;
    for (const nlohmann::json& r : rows) {
      f << csvField(r["name"]) << "," << csvField(r["scene"]) << ","
        << csvField(r.value("resolved_method", r.value("method", ""))) << "," << csvNumber(r, P("/spp")) << ","
        << csvNumber(r, P("/width")) << "," << csvNumber(r, P("/height")) << "," << csvNumber(r, P("/seed")) << ","
        << csvField(r["options"].dump()) << "," << r["status"].get<std::string>() << "," << csvField(r.value("error", ""))
        << "," << csvNumber(r, P("/timings/load_seconds")) << "," << csvNumber(r, P("/timings/build_seconds")) << ","
        << csvNumber(r, P("/timings/prepare_seconds")) << "," << csvNumber(r, P("/timings/render_seconds")) << ","
        << csvNumber(r, P("/timings/total_seconds")) << "," << csvNumber(r, P("/peak_rss_bytes"), 1e-6) << ","
        << csvNumber(r, P("/field_bytes"), 1e-6) << ","
        << csvField(r.value("accel_stats", nlohmann::json::object()).value("kind", "")) << ","
        << csvNumber(r, P("/accel_stats/bytes"), 1e-6) << "," << csvNumber(r, P("/threads_used")) << ","
        << csvField(r.value("reference", "")) << ","
        << csvNumber(r, P("/metrics/relmse")) << "," << csvNumber(r, P("/metrics/mse")) << ","
        << csvNumber(r, P("/metrics/psnr_srgb8")) << "," << csvNumber(r, P("/metrics/ssim")) << "\n";
    }
    if (!f) throw Error("cannot write " + tmp);
  });
}



Manifest loadManifest(const std::string& path, const std::string& outDir) {
  nlohmann::json manifest;
  {
    std::ifstream f(path);
    if (!f) throw SettingsError("cannot read manifest " + path);
    try {
      manifest = nlohmann::json::parse(f);
    } catch (const nlohmann::json::parse_error& e) {
      throw SettingsError(path + ": not valid JSON (" + std::string(e.what()) + ")");
    }
  }
  Manifest m;
  m.path = fs::absolute(path).string();
  const fs::path base = fs::path(m.path).parent_path();
  m.jobs = expandManifest(manifest, base);
  m.outDir = !outDir.empty() ? fs::path(outDir)
             : manifest.contains("output_dir") && manifest["output_dir"].is_string()
                 ? fs::path(resolvePath(base, manifest["output_dir"].get<std::string>()))
                 : base / fs::path(path).stem();
  return m;
}

std::vector<Job> shardJobs(const std::vector<Job>& jobs, size_t i, size_t n) {
  std::vector<Job> mine;
  for (size_t k = i; k < jobs.size(); k += n) mine.push_back(jobs[k]);
  return mine;
}

BatchReport runJobs(const std::vector<Job>& jobs, const fs::path& outDir, const std::string& stem,
                    const BatchSettings& o, const nlohmann::json& info) {
  fs::create_directories(outDir);
  std::vector<JobResult> results(jobs.size());
  std::map<std::string, Image> refs;
  std::mutex refsMutex, printMutex;
  size_t finished = 0;
  // Jobs in flight (-j) are TBB tasks, each waiting on its child process; each child renders
  // with -t threads. A job's outputs are its render's own atomic writes: a job interrupted or
  // failed leaves none, and --skip-existing takes a job whose sidecar (written last) is there.
  // SIGINT / SIGTERM: no job starts any more, and the renders running get SIGTERM at once
  // (kill -TERM of the batch alone reaches only the batch; a scheduler's signal to the whole
  // job reaches them too).
  std::atomic<bool> batchDone{false};
  std::thread watcher([&] {
    while (!batchDone.load()) {
      if (interruptRequested()) {
        signalChildren(SIGTERM);
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  });
  Timer elapsed;
  tbb::task_arena arena(std::max(1, o.jobsInFlight));
  arena.execute([&] {
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, jobs.size(), 1),
        [&](const tbb::blocked_range<size_t>& range) {
          for (size_t k = range.begin(); k != range.end(); ++k) {
            const Job& job = jobs[k];
            JobResult& r = results[k];
            if (interruptRequested()) {
              r.status = "not run";
              r.error = "interrupted";
              continue;
            }
            if (o.skipExisting && completeOutputs(outDir, job.name)) r.status = "existing";
            else r = runJob(job, outDir, o);
            if (r.status == "ok" || r.status == "existing") readOutputs(job, outDir, refs, refsMutex, r);
            std::lock_guard<std::mutex> lock(printMutex);
            ++finished;
            if (!o.quiet) {
              // Elapsed and, from the jobs finished so far, the time the rest will take.
              const double sec = elapsed.seconds();
              const double eta = sec / double(finished) * double(jobs.size() - finished);
              std::fprintf(stderr, "[%zu/%zu] %s elapsed %s eta %s: %s%s%s\n", finished, jobs.size(), job.name.c_str(),
                           formatDuration(sec).c_str(), formatDuration(eta).c_str(), r.status.c_str(),
                           r.error.empty() ? "" : ": ", r.error.c_str());
            }
          }
        },
        tbb::simple_partitioner());
  });
  batchDone = true;
  watcher.join();

  std::vector<nlohmann::json> rows;
  std::map<std::string, size_t> counts;
  for (size_t k = 0; k < jobs.size(); ++k) {
    rows.push_back(resultRow(jobs[k], results[k]));
    ++counts[results[k].status];
  }
  BatchReport report;
  for (size_t k = 0; k < jobs.size(); ++k) {
    report.rows.push_back(resultRow(jobs[k], results[k]));
    ++report.counts[results[k].status];
  }
  writeTables(report.rows, stem, info);
  report.interrupted = interruptRequested();
  return report;
}

MergeReport mergeShards(const std::vector<Job>& jobs, const fs::path& outDir) {
  std::map<std::string, std::pair<fs::file_time_type, nlohmann::json>> reported;  // name -> newest row
  std::error_code ec;
  if (fs::is_directory(outDir, ec))
    for (const auto& e : fs::directory_iterator(outDir)) {
      const std::string file = e.path().filename().string();
      if (file.rfind("results-shard-", 0) != 0 || e.path().extension() != ".json") continue;
      try {
        std::ifstream f(e.path());
        const nlohmann::json doc = nlohmann::json::parse(f);
        const auto when = fs::last_write_time(e.path());
        for (const nlohmann::json& row : doc.at("rows")) {
          const std::string name = row.at("name");
          auto it = reported.find(name);
          if (it == reported.end() || it->second.first < when) reported[name] = {when, row};
        }
      } catch (const std::exception& ex) {
        std::fprintf(stderr, "voxcone: warning: skipping %s: %s\n", e.path().string().c_str(), ex.what());
      }
    }
  MergeReport report;
  std::map<std::string, Image> refs;
  std::mutex refsMutex;
  for (const Job& job : jobs) {
    JobResult r;
    if (completeOutputs(outDir, job.name)) {
      r.status = "ok";
      readOutputs(job, outDir, refs, refsMutex, r);
    } else {
      auto it = reported.find(job.name);
      const std::string said = it != reported.end() ? it->second.second.value("status", "") : "";
      r.status = said.empty() || said == "ok" || said == "existing" ? "missing" : said;
      r.error = it != reported.end() ? it->second.second.value("error", "") : "no shard has run it";
      if (r.status == "missing" && !said.empty()) r.error = "its outputs are gone or incomplete";
    }
    if (r.status != "ok")
      report.notComplete.push_back(job.name + ": " + r.status + (r.error.empty() ? "" : " (" + r.error + ")"));
    ++report.counts[r.status];
    report.rows.push_back(resultRow(job, r));
  }
  return report;
}

size_t slurmShards(const SlurmSettings& slurm, size_t jobs) {
  return slurm.shards > 0 ? std::min(slurm.shards, jobs) : jobs;
}

std::string slurmScript(const SlurmSettings& slurm, const BatchSettings& batch, const std::string& manifestPath,
                        const fs::path& outDir, size_t jobs) {
  const size_t shards = slurmShards(slurm, jobs);
  std::ostringstream s;
  s << "#!/bin/sh\n";
  s << "#SBATCH --job-name=voxcone-" << slug(fs::path(manifestPath).stem().string()) << "\n";
  s << "#SBATCH --array=0-" << shards - 1;
  if (slurm.arrayLimit > 0) s << "%" << slurm.arrayLimit;
  s << "\n";
  s << "#SBATCH --output=" << (outDir / "slurm").string() << "/%x-%A_%a.log\n";
  s << "#SBATCH --open-mode=append\n";
  s << "#SBATCH --requeue\n";
  if (batch.threadsPerJob > 0) s << "#SBATCH --cpus-per-task=" << batch.threadsPerJob * std::max(1, batch.jobsInFlight) << "\n";
  if (!slurm.partition.empty()) s << "#SBATCH --partition=" << slurm.partition << "\n";
  if (!slurm.timeLimit.empty()) s << "#SBATCH --time=" << slurm.timeLimit << "\n";
  s << "# Written by 'voxcone batch --slurm'; it may also be submitted by hand: sbatch THIS_FILE\n";
  s << "# (one task: sbatch --array=I THIS_FILE). Join the shards' results: voxcone batch MANIFEST -o OUT --merge\n";
  s << "exec " << shellQuote(executableOf(batch)) << " batch "
    << shellQuote(manifestPath) << " -o " << shellQuote(outDir.string()) << " --shard \"${SLURM_ARRAY_TASK_ID}/"
    << shards << "\" --skip-existing -q -j " << batch.jobsInFlight << " -t " << batch.threadsPerJob;
  if (batch.memoryBudgetMb > 0.0) s << " --memory-budget-mb " << batch.memoryBudgetMb;
  s << "\n";
  return s.str();
}

std::string parseSbatchJobId(const std::string& out) {
  static const std::regex kId("([0-9]+)(;[^\\s]*)?\\s*$");
  std::smatch m;
  if (!std::regex_search(out, m, kId)) throw Error("sbatch gave no job id: " + lastLine(out));
  return m[1];
}

namespace {

/// Run `cmd`, its stdout and stderr; Error naming `what` when it fails.
std::string runOrThrow(const std::string& cmd, const std::string& what) {
  std::string out;
  const int code = runCapture(cmd + " 2>&1", out);
  if (code == 127) throw Error(what + ": command not found (is Slurm installed here?)");
  if (code != 0) throw Error(what + " failed (exit status " + std::to_string(code) + "): " + lastLine(out));
  return out;
}

}  // namespace

std::pair<std::string, std::string> submitSlurm(const SlurmSettings& slurm, const BatchSettings& batch,
                                                const std::string& manifestPath, const fs::path& outDir, size_t jobs) {
  fs::create_directories(outDir / "slurm");
  const std::string script = (outDir / "slurm" / (fs::path(manifestPath).stem().string() + ".sbatch")).string();
  writeFileAtomic(script, [&](const std::string& tmp) {
    std::ofstream f(tmp);
    f << slurmScript(slurm, batch, manifestPath, outDir, jobs);
    if (!f) throw Error("cannot write " + tmp);
  });
  fs::permissions(script, fs::perms::owner_exec | fs::perms::group_exec, fs::perm_options::add);
  return {parseSbatchJobId(runOrThrow("sbatch --parsable " + shellQuote(script), "sbatch")), script};
}

void waitForSlurmJob(const std::string& id) {
  for (;;) {
    std::string out;
    const int code = runCapture("squeue -h -j " + id + " -o %i 2>/dev/null", out);
    if (code == 0 && out.find_first_not_of(" \n") == std::string::npos) return;
    if (interruptRequested()) throw CancelledError("stopped waiting; the job array " + id + " keeps running");
    std::this_thread::sleep_for(std::chrono::seconds(2));
  }
}

}  // namespace voxcone

// `voxcone study structures` (the HBVH against a plain AABB BVH and an SAH kd-tree: build time,
// memory and render time of the same image, per mesh) and `voxcone study scaling` (time against
// thread count and against triangle count). Both are batches of `voxcone render` (resumable,
// one render at a time so that timings are not shared) with CSV, JSON and a chart.

#include "cli_util.h"
#include "commands.h"
#include "default_scene.h"
#include "voxcone/accel/accel.h"
#include "voxcone/core/error.h"
#include "voxcone/core/file_io.h"
#include "voxcone/core/parallel.h"
#include "voxcone/image/image_io.h"
#include "voxcone/image/metrics.h"
#include "voxcone/scene/generate.h"

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>

namespace voxcone {

namespace fs = std::filesystem;

namespace {

/// outDir/meshes/knot-N.ply, generated unless it is already there (the file is written
/// atomically, so an existing one is whole).
std::string generatedMesh(const std::string& outDir, uint64_t triangles) {
  fs::create_directories(outDir + "/meshes");
  const std::string path = fs::absolute(outDir + "/meshes/knot-" + std::to_string(triangles) + ".ply").string();
  if (!fs::exists(path)) writePly(path, makeKnotMesh(triangles));
  return path;
}

/// A scene of `meshPath` alone in the Cornell room of the built-in scene (its two blocks left
/// out), white, scaled to span 300 mm across its wider horizontal side (at most 400 mm high) and
/// standing on the floor where the canonical scenes' dragon stands. Written to
/// outDir/scenes/<mesh stem>.json; returns that path.
std::string writeMeshScene(const std::string& meshPath, const std::string& outDir) {
  if (!fs::exists(meshPath)) throw SettingsError("mesh not found: " + meshPath);
  const Bounds3 b = loadMesh(meshPath).bounds();
  if (b.empty()) throw SettingsError("mesh has no vertices: " + meshPath);
  const Vec3 d = b.diagonal();
  const float scale = std::min(300.0f / std::max({d.x, d.z, 1e-20f}), 400.0f / std::max(d.y, 1e-20f));
  const Vec3 c = b.center();
  nlohmann::json scene = nlohmann::json::parse(kDefaultSceneJson);
  nlohmann::json shapes = nlohmann::json::array();
  for (const nlohmann::json& s : scene["shapes"]) {
    const std::string name = s.value("name", "");
    if (name.rfind("short_block", 0) != 0 && name.rfind("tall_block", 0) != 0) shapes.push_back(s);
  }
  shapes.push_back({{"type", "mesh"},
                    {"name", fs::path(meshPath).stem().string()},
                    {"material", "white"},
                    {"file", fs::absolute(meshPath).string()},
                    {"transform",
                     {{"scale", scale}, {"translate", {278.0f - scale * c.x, -scale * b.lo.y, 279.6f - scale * c.z}}}}});
  scene["shapes"] = shapes;
  fs::create_directories(outDir + "/scenes");
  const std::string path = fs::absolute(outDir + "/scenes/" + fs::path(meshPath).stem().string() + ".json").string();
  writeJsonAtomic(path, scene);
  return path;
}

/// Pixels whose linear values differ at all, and the relMSE, of image `a` against `b`.
nlohmann::json imageDifference(const std::string& a, const std::string& b) {
  const Image ia = readImage(a), ib = readImage(b);
  const ImageMetrics m = compareImages(ia, ib);
  size_t differing = 0;
  for (size_t i = 0; i < ia.pixels.size(); ++i) differing += ia.pixels[i] != ib.pixels[i];
  return {{"pixels_differing", differing}, {"pixels", ia.pixels.size()}, {"relmse", m.relMse}};
}

/// Least-squares slope of log y against log x (the exponent of a power law); NaN for fewer than
/// two distinct x.
double logLogSlope(const std::vector<double>& x, const std::vector<double>& y) {
  const size_t n = x.size();
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (size_t i = 0; i < n; ++i) {
    const double lx = std::log(x[i]), ly = std::log(y[i]);
    sx += lx;
    sy += ly;
    sxx += lx * lx;
    sxy += lx * ly;
  }
  const double den = double(n) * sxx - sx * sx;
  return n >= 2 && den > 1e-12 ? (double(n) * sxy - sx * sy) / den : std::numeric_limits<double>::quiet_NaN();
}

nlohmann::json num(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }

/// The number at JSON pointer `pointer` in a batch row, or NaN.
double at(const nlohmann::json& row, const char* pointer) {
  const nlohmann::json::json_pointer p(pointer);
  return row.contains(p) && row[p].is_number() ? row[p].get<double>() : std::numeric_limits<double>::quiet_NaN();
}

bool succeeded(const nlohmann::json& row) { return row["status"] == "ok" || row["status"] == "existing"; }

void writeCsv(const std::string& path, const std::vector<std::string>& columns, const nlohmann::json& rows) {
  writeFileAtomic(path, [&](const std::string& tmp) {
    std::ofstream f(tmp);
    for (size_t i = 0; i < columns.size(); ++i) f << (i ? "," : "") << columns[i];
    f << "\n";
    for (const nlohmann::json& r : rows) {
      for (size_t i = 0; i < columns.size(); ++i) {
        const nlohmann::json& v = r.contains(columns[i]) ? r[columns[i]] : nlohmann::json();
        f << (i ? "," : "") << (v.is_null() ? std::string() : v.is_string() ? v.get<std::string>() : v.dump());
      }
      f << "\n";
    }
    if (!f) throw Error("cannot write " + tmp);
  });
}

struct StructuresOptions {
  std::vector<std::string> meshes;
  std::vector<uint64_t> generate;
  std::vector<std::string> accels = accelKinds();
  std::string method = "path";
  int spp = 4;
  std::string resolution = "256x256";
  int threads = 0;
  std::string outDir = "out/study-structures";
  bool quick = false;
  bool noChart = false;
  std::string plotScript;  // empty: dataPath("tools/plot_study.py")
};

void runStructuresStudy(StructuresOptions o) {
  if (o.quick) {
    if (o.generate.empty()) o.generate = {2000, 20000};
    o.resolution = "24x24";
    o.spp = 1;
  } else if (o.meshes.empty() && o.generate.empty()) {
    // The study's meshes: the bunny and the dragon (tools/fetch_models.sh) and 10M triangles.
    for (const char* m : {"bunny.ply", "dragon_vrip.ply"}) {
      const std::string p = dataPath(std::string("data/models/") + m);
      if (fs::exists(p)) o.meshes.push_back(fs::canonical(p).string());
      else std::fprintf(stderr, "study structures: %s missing (bash tools/fetch_models.sh), left out\n", m);
    }
    o.generate = {10000000};
  }
  fs::create_directories(o.outDir);
  std::vector<std::string> meshes = o.meshes;
  for (uint64_t n : o.generate) meshes.push_back(generatedMesh(o.outDir, n));
  if (meshes.empty()) throw SettingsError("study structures: no meshes");
  nlohmann::json jobs = nlohmann::json::array();
  std::vector<std::string> scenes;
  for (const std::string& m : meshes) {
    scenes.push_back(writeMeshScene(m, o.outDir));
    for (const std::string& a : o.accels) jobs.push_back({{"scene", scenes.back()}, {"accel", a}});
  }
  const nlohmann::json manifest = {
      {"defaults", {{"method", o.method}, {"spp", o.spp}, {"res", o.resolution}}}, {"jobs", jobs}};
  const nlohmann::json results = runStudyBatch(manifest, o.outDir, 1, o.threads);

  // One row per render; ratios and the image difference against the HBVH's render of the mesh.
  nlohmann::json rows = nlohmann::json::array();
  std::map<std::string, nlohmann::json> hbvhOf;
  for (const nlohmann::json& r : results["rows"])
    if (succeeded(r) && r["accel"] == "hbvh") hbvhOf[r["scene"].get<std::string>()] = r;
  for (const nlohmann::json& r : results["rows"]) {
    if (!succeeded(r)) {
      std::fprintf(stderr, "study structures: %s failed: %s\n", r["name"].get<std::string>().c_str(),
                   r.value("error", "").c_str());
      continue;
    }
    nlohmann::json row = {{"mesh", fs::path(r["scene"].get<std::string>()).stem().string()},
                          {"accel", r["accel"]},
                          {"triangles", r["triangles"]},
                          {"build_s", num(at(r, "/accel_stats/build_seconds"))},
                          {"accel_mb", num(at(r, "/accel_stats/bytes") * 1e-6)},
                          {"render_s", num(at(r, "/timings/render_seconds"))},
                          {"total_s", num(at(r, "/timings/total_seconds"))},
                          {"peak_rss_mb", num(at(r, "/peak_rss_bytes") * 1e-6)},
                          {"accel_stats", r["accel_stats"]}};
    const auto base = hbvhOf.find(r["scene"].get<std::string>());
    if (base != hbvhOf.end()) {
      const nlohmann::json& h = base->second;
      row["build_vs_hbvh"] = num(at(r, "/accel_stats/build_seconds") / at(h, "/accel_stats/build_seconds"));
      row["memory_vs_hbvh"] = num(at(r, "/accel_stats/bytes") / at(h, "/accel_stats/bytes"));
      row["render_vs_hbvh"] = num(at(r, "/timings/render_seconds") / at(h, "/timings/render_seconds"));
      const nlohmann::json diff = imageDifference(r["outputs"]["exr"], h["outputs"]["exr"]);
      row["pixels_differing_from_hbvh"] = diff["pixels_differing"];
      row["relmse_vs_hbvh"] = diff["relmse"];
    }
    rows.push_back(row);
  }
  const std::string stem = o.outDir + "/structures";
  writeJsonAtomic(stem + ".json", {{"study", "structures"},
                                   {"method", o.method},
                                   {"spp", o.spp},
                                   {"res", o.resolution},
                                   {"threads", o.threads},
                                   {"rows", rows}});
  writeCsv(stem + ".csv",
           {"mesh", "accel", "triangles", "build_s", "accel_mb", "render_s", "total_s", "peak_rss_mb", "build_vs_hbvh",
            "memory_vs_hbvh", "render_vs_hbvh", "pixels_differing_from_hbvh", "relmse_vs_hbvh"},
           rows);
  std::printf("%-22s %-7s %10s %9s %9s %9s %7s %7s %7s %9s\n", "mesh", "accel", "triangles", "build s", "MB",
              "render s", "build", "memory", "render", "pixels");
  std::printf("%-22s %-7s %10s %9s %9s %9s %7s %7s %7s %9s\n", "", "", "", "", "", "", "/hbvh", "/hbvh", "/hbvh",
              "differ");
  for (const nlohmann::json& r : rows) {
    auto f = [&](const char* k) { return r.contains(k) && r[k].is_number() ? r[k].get<double>() : NAN; };
    std::printf("%-22s %-7s %10.0f %9.3f %9.1f %9.3f %7.2f %7.2f %7.2f %9.0f\n",
                r["mesh"].get<std::string>().substr(0, 22).c_str(), r["accel"].get<std::string>().c_str(),
                f("triangles"), f("build_s"), f("accel_mb"), f("render_s"), f("build_vs_hbvh"), f("memory_vs_hbvh"),
                f("render_vs_hbvh"), f("pixels_differing_from_hbvh"));
  }
  std::printf("wrote %s.csv, %s.json\n", stem.c_str(), stem.c_str());
  if (!o.noChart) runChartScript(o.plotScript.empty() ? dataPath("tools/plot_study.py") : o.plotScript, stem + ".json", stem);
}

struct ScalingOptions {
  std::string scenePath;
  std::vector<int> threadCounts;
  std::vector<uint64_t> triangles;
  std::vector<std::string> methods = {"path", "voxcone"};
  int spp = 4;
  std::string resolution = "256x256";
  int threads = 0;  ///< for the triangle-count renders
  std::string outDir = "out/study-scaling";
  bool quick = false;
  bool noChart = false;
  std::string plotScript;  // empty: dataPath("tools/plot_study.py")
};

void runScalingStudy(ScalingOptions o) {
  if (!fs::exists(o.scenePath)) throw SettingsError("scene file not found: " + o.scenePath);
  if (o.quick) {
    if (o.threadCounts.empty()) o.threadCounts = {1, 2};
    if (o.triangles.empty()) o.triangles = {1000, 4000};
    o.resolution = "24x24";
    o.spp = 1;
  }
  if (o.threadCounts.empty()) {
    // 1, 2, 4, ... and the machine's count.
    const int hw = hardwareThreads();
    for (int t = 1; t < hw; t *= 2) o.threadCounts.push_back(t);
    o.threadCounts.push_back(hw);
  }
  if (o.triangles.empty()) o.triangles = {10000, 100000, 1000000, 10000000};
  fs::create_directories(o.outDir);
  const std::string scene = fs::absolute(o.scenePath).string();
  nlohmann::json jobs = nlohmann::json::array();
  nlohmann::json voxconeQuick = o.quick ? nlohmann::json{{"level", 4}, {"photons", 4000}} : nlohmann::json::object();
  auto options = [&](const std::string& m) { return m == "voxcone" ? voxconeQuick : nlohmann::json::object(); };
  for (const std::string& m : o.methods)
    for (int t : o.threadCounts) jobs.push_back({{"scene", scene}, {"method", m}, {"threads", t}, {"options", options(m)}});
  std::map<std::string, uint64_t> generatedTriangles;  // scene path -> requested count
  for (uint64_t n : o.triangles) {
    const std::string s = writeMeshScene(generatedMesh(o.outDir, n), o.outDir);
    generatedTriangles[s] = n;
    for (const std::string& m : o.methods)
      jobs.push_back({{"scene", s}, {"method", m}, {"threads", o.threads}, {"options", options(m)}});
  }
  const nlohmann::json manifest = {{"defaults", {{"spp", o.spp}, {"res", o.resolution}}}, {"jobs", jobs}};
  const nlohmann::json results = runStudyBatch(manifest, o.outDir, 1, o.threads);

  nlohmann::json threadRows = nlohmann::json::array(), triangleRows = nlohmann::json::array();
  std::map<std::string, nlohmann::json> oneThread;  // method -> its 1-thread render
  for (const nlohmann::json& r : results["rows"])
    if (succeeded(r) && r["scene"] == scene && r["threads"] == 1) oneThread[r["method"].get<std::string>()] = r;
  std::map<std::string, std::vector<double>> tris, build, render, total;
  for (const nlohmann::json& r : results["rows"]) {
    if (!succeeded(r)) {
      std::fprintf(stderr, "study scaling: %s failed: %s\n", r["name"].get<std::string>().c_str(),
                   r.value("error", "").c_str());
      continue;
    }
    const std::string m = r["method"].get<std::string>();
    if (r["scene"] == scene) {
      nlohmann::json row = {{"method", m},
                            {"threads", r["threads"]},
                            {"render_s", num(at(r, "/timings/render_seconds"))},
                            {"total_s", num(at(r, "/timings/total_seconds"))}};
      const auto one = oneThread.find(m);
      if (one != oneThread.end()) {
        const double speedup = at(one->second, "/timings/total_seconds") / at(r, "/timings/total_seconds");
        row["speedup"] = num(speedup);
        row["efficiency"] = num(speedup / r["threads"].get<double>());
        row["render_speedup"] = num(at(one->second, "/timings/render_seconds") / at(r, "/timings/render_seconds"));
        row["pixels_differing_from_1_thread"] =
            imageDifference(r["outputs"]["exr"], one->second["outputs"]["exr"])["pixels_differing"];
      }
      threadRows.push_back(row);
    } else {
      const double n = at(r, "/triangles");
      triangleRows.push_back({{"method", m},
                              {"triangles", r["triangles"]},
                              {"requested_triangles", generatedTriangles[r["scene"].get<std::string>()]},
                              {"build_s", num(at(r, "/accel_stats/build_seconds"))},
                              {"prepare_s", num(at(r, "/timings/prepare_seconds"))},
                              {"render_s", num(at(r, "/timings/render_seconds"))},
                              {"total_s", num(at(r, "/timings/total_seconds"))},
                              {"peak_rss_mb", num(at(r, "/peak_rss_bytes") * 1e-6)}});
      tris[m].push_back(n);
      build[m].push_back(at(r, "/accel_stats/build_seconds"));
      render[m].push_back(at(r, "/timings/render_seconds"));
      total[m].push_back(at(r, "/timings/total_seconds"));
    }
  }
  // How each cost grows with the triangle count: the exponent of a power-law fit.
  nlohmann::json slopes = nlohmann::json::object();
  for (const auto& [m, x] : tris)
    slopes[m] = {{"build", num(logLogSlope(x, build[m]))}, {"render", num(logLogSlope(x, render[m]))},
                 {"total", num(logLogSlope(x, total[m]))}};
  const std::string stem = o.outDir + "/scaling";
  writeJsonAtomic(stem + ".json", {{"study", "scaling"},
                                   {"scene", o.scenePath},
                                   {"spp", o.spp},
                                   {"res", o.resolution},
                                   {"hardware_threads", hardwareThreads()},
                                   {"threads", threadRows},
                                   {"triangles", triangleRows},
                                   {"triangle_exponents", slopes}});
  writeCsv(stem + "-threads.csv",
           {"method", "threads", "render_s", "total_s", "speedup", "render_speedup", "efficiency",
            "pixels_differing_from_1_thread"},
           threadRows);
  writeCsv(stem + "-triangles.csv",
           {"method", "triangles", "requested_triangles", "build_s", "prepare_s", "render_s", "total_s", "peak_rss_mb"},
           triangleRows);
  auto f = [](const nlohmann::json& r, const char* k) { return r.contains(k) && r[k].is_number() ? r[k].get<double>() : NAN; };
  std::printf("%-8s %7s %9s %9s %8s %10s %8s\n", "method", "threads", "render s", "total s", "speedup", "efficiency",
              "differ");
  for (const nlohmann::json& r : threadRows)
    std::printf("%-8s %7.0f %9.3f %9.3f %8.2f %10.2f %8.0f\n", r["method"].get<std::string>().c_str(),
                f(r, "threads"), f(r, "render_s"), f(r, "total_s"), f(r, "speedup"), f(r, "efficiency"),
                f(r, "pixels_differing_from_1_thread"));
  std::printf("%-8s %10s %9s %9s %9s %9s\n", "method", "triangles", "build s", "prepare s", "render s", "total s");
  for (const nlohmann::json& r : triangleRows)
    std::printf("%-8s %10.0f %9.3f %9.3f %9.3f %9.3f\n", r["method"].get<std::string>().c_str(), f(r, "triangles"),
                f(r, "build_s"), f(r, "prepare_s"), f(r, "render_s"), f(r, "total_s"));
  for (const auto& [m, s] : slopes.items())
    std::printf("%s: time ~ triangles^k, k = %.2f (build), %.2f (render), %.2f (total)\n", m.c_str(),
                s["build"].is_number() ? s["build"].get<double>() : NAN,
                s["render"].is_number() ? s["render"].get<double>() : NAN,
                s["total"].is_number() ? s["total"].get<double>() : NAN);
  std::printf("wrote %s.json, %s-threads.csv, %s-triangles.csv\n", stem.c_str(), stem.c_str(), stem.c_str());
  if (!o.noChart) runChartScript(o.plotScript.empty() ? dataPath("tools/plot_study.py") : o.plotScript, stem + ".json", stem);
}

}  // namespace

void addStructureStudies(CLI::App& study) {
  auto so = std::make_shared<StructuresOptions>();
  CLI::App* s = study.add_subcommand(
      "structures", "HBVH against a plain AABB BVH and an SAH kd-tree: build time, memory, render time per mesh");
  s->add_option("meshes", so->meshes, "Meshes (PLY/OBJ); default: bunny, dragon and a generated 10M-triangle knot")
      ->default_str("bunny, dragon (tools/fetch_models.sh) and a generated 10M-triangle knot");
  s->add_option("--generate", so->generate, "Also generated knot meshes of these triangle counts")
      ->default_str("none");
  s->add_option("--accels", so->accels, "Structures to compare")->check(CLI::IsMember(accelKinds()))->delimiter(',');
  s->add_option("--method", so->method, "Integrator of the renders");
  s->add_option("--spp", so->spp, "Samples per pixel")->check(CLI::Range(1, 1 << 20));
  s->add_option("--res", so->resolution, "Resolution");
  s->add_option("-t,--threads", so->threads, "Threads per render (0 = all)")->check(CLI::Range(0, 4096));
  s->add_option("-o,--output", so->outDir, "Output folder");
  s->add_flag("--quick", so->quick, "Two small generated meshes at 24x24, 1 spp (for tests)");
  s->add_option("--plot-script", so->plotScript, "Chart script (python3-matplotlib)")
      ->default_str("<data>/tools/plot_study.py");
  s->add_flag("--no-chart", so->noChart, "Write CSV and JSON only");
  s->callback([so] { runStructuresStudy(*so); });

  auto sc = std::make_shared<ScalingOptions>();
  CLI::App* c = study.add_subcommand("scaling", "Time against thread count and against triangle count");
  c->add_option("scene", sc->scenePath, "Scene for the thread-count renders (JSON)")->required();
  c->add_option("--thread-counts", sc->threadCounts, "Thread counts")
      ->check(CLI::Range(1, 4096))
      ->delimiter(',')
      ->default_str("1, 2, 4, ... all");
  c->add_option("--triangles", sc->triangles, "Generated knot sizes")->delimiter(',')
      ->default_str("10k, 100k, 1M, 10M");
  c->add_option("--methods", sc->methods, "Integrators")->delimiter(',');
  c->add_option("--spp", sc->spp, "Samples per pixel")->check(CLI::Range(1, 1 << 20));
  c->add_option("--res", sc->resolution, "Resolution");
  c->add_option("-t,--threads", sc->threads, "Threads of the triangle-count renders (0 = all)")
      ->check(CLI::Range(0, 4096));
  c->add_option("-o,--output", sc->outDir, "Output folder");
  c->add_flag("--quick", sc->quick, "1 and 2 threads, 1000 and 4000 triangles, 24x24, 1 spp (for tests)");
  c->add_option("--plot-script", sc->plotScript, "Chart script (python3-matplotlib)")
      ->default_str("<data>/tools/plot_study.py");
  c->add_flag("--no-chart", sc->noChart, "Write CSV and JSON only");
  c->callback([sc] { runScalingStudy(*sc); });
}

}  // namespace voxcone

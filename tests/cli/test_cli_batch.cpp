// `voxcone batch`: grid expansion and deterministic names, parallel jobs with the same images as
// serial ones, a failed job recorded while the batch goes on, --skip-existing, --shard, the
// memory budget, and metrics against a reference that match `compare`.

#include "voxcone/image/image_io.h"
#include "voxcone/image/metrics.h"

#include "../support/temp_dir.h"
#include "../support/test_scenes.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <csignal>

#include <filesystem>
#include <fstream>
#include <set>
#include <vector>

namespace voxcone {
namespace {

namespace fs = std::filesystem;

class Batch : public test::TempDirTest {
protected:
  /// Run `voxcone ARGS`; returns the exit code, stdout in m_out.
  int run(const std::string& args) {
    const std::string cmd = std::string(VOXCONE_CLI_PATH) + " " + args + " >" + path("stdout.txt") + " 2>" + path("stderr.txt");
    const int status = std::system(cmd.c_str());
    std::ifstream f(path("stdout.txt"));
    m_out.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }
  std::string writeManifest(const nlohmann::json& m, const std::string& name = "manifest.json") {
    std::ofstream(path(name)) << m.dump(1);
    return path(name);
  }
  nlohmann::json readJson(const std::string& p) {
    std::ifstream f(p);
    return nlohmann::json::parse(f);
  }
  /// A grid of 2 spp values x 2 levels of voxcone plus one path job, tiny.
  nlohmann::json gridManifest(const std::string& reference = "") {
    nlohmann::json m = {
        {"defaults", {{"scene", test::sourceDir() + "/data/scenes/cornell-box.json"}, {"res", "12x12"}}},
        {"jobs", {{{"name", "path-ref"}, {"method", "path"}, {"spp", 2}}}},
        {"grid", {{{"method", "voxcone"}, {"spp", {1, 2}}, {"options", {{"level", {4, 5}}, {"photons", 2000}}}}}}};
    if (!reference.empty()) m["reference"] = reference;
    return m;
  }
  /// Start `voxcone batch MANIFEST -o runs -j 1 -t 1` (stderr to batch-stderr.txt); its pid.
  pid_t startBatch(const std::string& manifest) {
    const std::string out = path("runs"), err = path("batch-stderr.txt");
    const pid_t pid = ::fork();
    if (pid == 0) {
      std::freopen(err.c_str(), "w", stderr);
      ::execl(VOXCONE_CLI_PATH, VOXCONE_CLI_PATH, "batch", manifest.c_str(), "-o", out.c_str(), "-j", "1", "-t", "1",
              static_cast<char*>(nullptr));
      ::_exit(127);
    }
    return pid;
  }
  std::string m_out;
};

/// Pids of processes whose command line contains `needle`.
std::vector<pid_t> processesWith(const std::string& needle) {
  std::vector<pid_t> out;
  for (const auto& e : fs::directory_iterator("/proc")) {
    const std::string name = e.path().filename().string();
    if (name.empty() || name.find_first_not_of("0123456789") != std::string::npos) continue;
    std::ifstream f(e.path() / "cmdline");
    std::string cmdline((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    if (cmdline.find(needle) != std::string::npos) out.push_back(pid_t(std::stol(name)));
  }
  return out;
}

/// Pids of the renders whose command line holds `tag` (not `batch` itself), once one has
/// started; empty after 60 s without one.
std::vector<pid_t> waitForRenders(const std::string& tag, pid_t batch) {
  std::vector<pid_t> renders;
  for (int i = 0; i < 600 && renders.empty(); ++i) {
    ::usleep(100000);
    for (pid_t p : processesWith(tag))
      if (p != batch) renders.push_back(p);
  }
  return renders;
}

TEST_F(Batch, ARenderDiesWithItsBatch) {
  // A batch killed with SIGKILL (no chance to clean up) used to leave its render running and
  // writing into the output folder; the render now gets SIGTERM with its parent's death.
  const std::string tag = "pdeath-" + std::to_string(::getpid());
  const std::string manifest = writeManifest(
      {{"defaults", {{"scene", test::sourceDir() + "/data/scenes/cornell-box.json"}, {"res", "64x64"}}},
       {"jobs", {{{"name", tag}, {"method", "path"}, {"spp", 1 << 20}}}}});
  const pid_t batch = startBatch(manifest);
  ASSERT_GE(batch, 0);
  // Wait (up to 60 s on a slow machine) for the render to start, then kill the batch.
  const std::vector<pid_t> renders = waitForRenders(tag, batch);
  ASSERT_FALSE(renders.empty()) << "the render never started";
  ::kill(batch, SIGKILL);
  ::waitpid(batch, nullptr, 0);
  bool gone = false;
  for (int i = 0; i < 600 && !gone; ++i) {
    ::usleep(100000);
    gone = true;
    for (pid_t p : renders) gone = gone && (::kill(p, 0) != 0 || processesWith(tag).empty());
  }
  EXPECT_TRUE(gone) << "the render outlived its batch";
}

TEST_F(Batch, SigtermStopsTheRendersAndRecordsThemInterrupted) {
  // SIGTERM to the batch alone (kill PID, not the process group): it passes it on to the render
  // running, records that job "interrupted" (no outputs: --skip-existing reruns it) and the one
  // not started "not run", writes its tables and exits 128 + SIGTERM.
  const std::string tag = "sigterm-" + std::to_string(::getpid());
  const std::string manifest = writeManifest(
      {{"defaults", {{"scene", test::sourceDir() + "/data/scenes/cornell-box.json"}, {"res", "16x16"}, {"method", "path"}}},
       {"jobs", {{{"name", tag}, {"spp", 1 << 20}}, {{"name", "after"}, {"spp", 1}}}}});
  const pid_t batch = startBatch(manifest);
  ASSERT_GE(batch, 0);
  const std::vector<pid_t> renders = waitForRenders(tag, batch);
  ASSERT_FALSE(renders.empty()) << "the render never started";
  ::usleep(300000);
  ::kill(batch, SIGTERM);
  int status = 0;
  for (int i = 0; i < 600 && ::waitpid(batch, &status, WNOHANG) != batch; ++i) ::usleep(100000);
  ASSERT_TRUE(WIFEXITED(status)) << "the batch did not stop";
  EXPECT_EQ(WEXITSTATUS(status), 128 + SIGTERM);
  const nlohmann::json results = readJson(path("runs/results.json"));
  ASSERT_EQ(results["rows"].size(), 2u);
  EXPECT_EQ(results["rows"][0]["status"], "interrupted");
  EXPECT_EQ(results["rows"][0]["error"], "stopped by SIGTERM");
  EXPECT_EQ(results["rows"][1]["status"], "not run");
  EXPECT_FALSE(fs::exists(path("runs/" + tag + ".exr")));
  for (pid_t p : renders) EXPECT_NE(::kill(p, 0), 0) << "the render outlived its batch";
}

TEST_F(Batch, GridExpandsIntoNamedJobsAndParallelEqualsSerial) {
  const std::string manifest = writeManifest(gridManifest());
  ASSERT_EQ(run("batch " + manifest + " --dry-run"), 0);
  // 1 job + 2 x 2 grid jobs, in order: axes in key order ("options" before "spp"), the last
  // varying fastest.
  std::istringstream lines(m_out);
  std::vector<std::string> names;
  for (std::string l; std::getline(lines, l);) names.push_back(l.substr(0, l.find(' ')));
  ASSERT_EQ(names.size(), 5u);
  EXPECT_EQ(names[0], "path-ref");
  EXPECT_EQ(names[1].rfind("cornell-box_voxcone_spp1_level4_photons2000_", 0), 0u) << names[1];
  EXPECT_EQ(names[2].rfind("cornell-box_voxcone_spp2_level4_photons2000_", 0), 0u) << names[2];
  EXPECT_EQ(names[4].rfind("cornell-box_voxcone_spp2_level5_photons2000_", 0), 0u) << names[4];
  // The names are the same on another run (they hash the settings, not the time or the order).
  const std::string first = m_out;
  ASSERT_EQ(run("batch " + manifest + " --dry-run"), 0);
  EXPECT_EQ(m_out, first);

  ASSERT_EQ(run("batch " + manifest + " -j 1 -t 1 -q -o " + path("serial")), 0) << m_out;
  ASSERT_EQ(run("batch " + manifest + " -j 3 -t 1 -q -o " + path("parallel")), 0) << m_out;
  for (const std::string& n : names) {
    const Image a = readImage(path("serial/" + n + ".exr")), b = readImage(path("parallel/" + n + ".exr"));
    ASSERT_EQ(a.pixels.size(), b.pixels.size());
    EXPECT_TRUE(a.pixels == b.pixels) << n;
  }
  const nlohmann::json t = readJson(path("parallel/results.json"));
  ASSERT_EQ(t["rows"].size(), 5u);
  for (size_t i = 0; i < names.size(); ++i) {
    const nlohmann::json& r = t["rows"][i];
    EXPECT_EQ(r["name"], names[i]);  // rows in manifest order, whatever finished first
    EXPECT_EQ(r["status"], "ok");
    EXPECT_EQ(r["width"], 12);
    EXPECT_GT(r["timings"]["total_seconds"].get<double>(), 0.0);
    EXPECT_GT(r["peak_rss_bytes"].get<double>(), 0.0);
    EXPECT_EQ(r.contains("field_bytes"), i > 0);  // voxcone jobs report their grid memory
  }
  // The CSV has a header and one line per job.
  std::ifstream csv(path("parallel/results.csv"));
  size_t csvLines = 0;
  for (std::string l; std::getline(csv, l);) ++csvLines;
  EXPECT_EQ(csvLines, 6u);
}

TEST_F(Batch, AFailedJobIsRecordedAndTheRestRun) {
  nlohmann::json m = gridManifest();
  m["jobs"].push_back({{"name", "missing"}, {"scene", "no-such-scene.json"}});
  m["jobs"].push_back({{"name", "bad-option"}, {"method", "voxcone"}, {"options", {{"no_such_option", 1}}}});
  m["jobs"].push_back({{"name", "bad-spp"}, {"method", "path"}, {"spp", 0}});
  const std::string manifest = writeManifest(m);
  EXPECT_EQ(run("batch " + manifest + " -j 2 -t 1 -q -o " + path("out")), 1);
  const nlohmann::json t = readJson(path("out/results.json"));
  ASSERT_EQ(t["rows"].size(), 8u);
  int ok = 0;
  for (const nlohmann::json& r : t["rows"]) {
    if (r["name"] == "missing" || r["name"] == "bad-option" || r["name"] == "bad-spp") {
      EXPECT_EQ(r["status"], "failed");
      EXPECT_FALSE(r["error"].get<std::string>().empty());
      EXPECT_FALSE(fs::exists(path("out/" + r["name"].get<std::string>() + ".exr")));
    } else {
      ok += r["status"] == "ok";
    }
  }
  EXPECT_EQ(ok, 5);
  EXPECT_NE(t["rows"][2]["error"].get<std::string>().find("no_such_option"), std::string::npos) << t["rows"][2];
  // The usage error itself, not CLI11's "Run with --help for more information." line.
  std::string spp;
  for (const nlohmann::json& r : t["rows"])
    if (r["name"] == "bad-spp") spp = r["error"].get<std::string>();
  EXPECT_NE(spp.find("--spp"), std::string::npos) << spp;
  EXPECT_EQ(spp.find("Run with"), std::string::npos) << spp;
}

TEST_F(Batch, SkipExistingAndShards) {
  const std::string manifest = writeManifest(gridManifest());
  // Two shards cover the jobs once between them.
  ASSERT_EQ(run("batch " + manifest + " --shard 0/2 -t 1 -q -o " + path("out")), 0);
  ASSERT_EQ(run("batch " + manifest + " --shard 1/2 -t 1 -q -o " + path("out")), 0);
  const nlohmann::json s0 = readJson(path("out/results-shard-0-of-2.json")), s1 = readJson(path("out/results-shard-1-of-2.json"));
  EXPECT_EQ(s0["rows"].size(), 3u);
  EXPECT_EQ(s1["rows"].size(), 2u);
  std::set<std::string> all;
  for (const auto* s : {&s0, &s1})
    for (const nlohmann::json& r : (*s)["rows"]) EXPECT_TRUE(all.insert(r["name"].get<std::string>()).second);
  EXPECT_EQ(all.size(), 5u);
  // Everything is there: --skip-existing runs nothing and tables the existing outputs.
  const auto stamp = fs::last_write_time(path("out/path-ref.exr"));
  ASSERT_EQ(run("batch " + manifest + " --skip-existing -t 1 -q -o " + path("out")), 0);
  EXPECT_EQ(fs::last_write_time(path("out/path-ref.exr")), stamp);
  const nlohmann::json t = readJson(path("out/results.json"));
  ASSERT_EQ(t["rows"].size(), 5u);
  for (const nlohmann::json& r : t["rows"]) {
    EXPECT_EQ(r["status"], "existing");
    EXPECT_GT(r["timings"]["render_seconds"].get<double>(), 0.0);
  }
  // An interrupted batch left some jobs undone: only those run.
  fs::remove(path("out/path-ref.json"));
  ASSERT_EQ(run("batch " + manifest + " --skip-existing -t 1 -q -o " + path("out")), 0);
  EXPECT_EQ(readJson(path("out/results.json"))["rows"][0]["status"], "ok");
  // The sidecar is not enough: a job whose EXR was deleted or truncated runs again.
  const nlohmann::json rows = readJson(path("out/results.json"))["rows"];
  const std::string deleted = rows[1]["name"], truncated = rows[2]["name"];
  fs::remove(path("out/" + deleted + ".exr"));
  fs::resize_file(path("out/" + truncated + ".exr"), 100);
  ASSERT_EQ(run("batch " + manifest + " --skip-existing -t 1 -q -o " + path("out")), 0);
  for (const nlohmann::json& r : readJson(path("out/results.json"))["rows"])
    EXPECT_EQ(r["status"], r["name"] == deleted || r["name"] == truncated ? "ok" : "existing") << r["name"];
  EXPECT_NE(run("batch " + manifest + " --shard 2/2"), 0);
}

TEST_F(Batch, StatusAndMergeJoinTheShardsAndNameWhatIsMissing) {
  // What a Slurm array leaves: shard tables and outputs. --merge joins them into one table in
  // manifest order (rows from the outputs, so a task killed before its table was written loses
  // nothing) and names what is missing; --status says the same without writing.
  const std::string manifest = writeManifest(gridManifest());
  ASSERT_EQ(run("batch " + manifest + " --shard 0/2 -t 1 -q -o " + path("out")), 0);
  EXPECT_EQ(run("batch " + manifest + " --status -o " + path("out")), 1);  // shard 1 never ran
  EXPECT_NE(m_out.find("3 complete"), std::string::npos) << m_out;
  EXPECT_NE(m_out.find("2 missing"), std::string::npos) << m_out;
  EXPECT_NE(m_out.find("no shard has run it"), std::string::npos) << m_out;
  ASSERT_EQ(run("batch " + manifest + " --shard 1/2 -t 1 -q -o " + path("out")), 0);
  ASSERT_EQ(run("batch " + manifest + " --status -o " + path("out")), 0) << m_out;
  EXPECT_FALSE(fs::exists(path("out/results.json")));  // --status writes nothing
  ASSERT_EQ(run("batch " + manifest + " --merge -o " + path("out")), 0) << m_out;
  const nlohmann::json merged = readJson(path("out/results.json"));
  ASSERT_EQ(merged["rows"].size(), 5u);
  // The same rows, in the same order, as one batch of the whole manifest.
  ASSERT_EQ(run("batch " + manifest + " -t 1 -q -o " + path("whole")), 0);
  const nlohmann::json whole = readJson(path("whole/results.json"));
  for (size_t i = 0; i < 5; ++i) {
    EXPECT_EQ(merged["rows"][i]["name"], whole["rows"][i]["name"]);
    EXPECT_EQ(merged["rows"][i]["status"], "ok");
    EXPECT_EQ(merged["rows"][i]["resolved_spp"], whole["rows"][i]["resolved_spp"]);
  }
  // An output lost since (a node's disk, a truncated copy): missing, and exit 1.
  const std::string lost = merged["rows"][3]["name"];
  fs::remove(path("out/" + lost + ".exr"));
  EXPECT_EQ(run("batch " + manifest + " --merge -o " + path("out")), 1);
  EXPECT_NE(m_out.find(lost + ": missing"), std::string::npos) << m_out;
  EXPECT_EQ(readJson(path("out/results.json"))["rows"][3]["status"], "missing");
  // One mode at a time; --wait only with --slurm.
  EXPECT_EQ(run("batch " + manifest + " --merge --status -o " + path("out")), 2);
  EXPECT_EQ(run("batch " + manifest + " --wait -o " + path("out")), 2);
}

TEST_F(Batch, SlurmScriptRunsEachShardWithSkipExisting) {
  // The script `--slurm` submits (printed by --dry-run, no Slurm needed): one array task per
  // shard, the shard count written in (a task resubmitted alone keeps its slice), resumable.
  const std::string manifest = writeManifest(gridManifest());
  ASSERT_EQ(run("batch " + manifest + " --slurm --shards 2 --partition gpu --time 10:00 --array-limit 1 -t 3 --dry-run -o " +
                path("out")),
            0);
  EXPECT_NE(m_out.find("#SBATCH --array=0-1%1\n"), std::string::npos) << m_out;
  EXPECT_NE(m_out.find("#SBATCH --partition=gpu\n"), std::string::npos) << m_out;
  EXPECT_NE(m_out.find("#SBATCH --time=10:00\n"), std::string::npos) << m_out;
  EXPECT_NE(m_out.find("#SBATCH --cpus-per-task=3\n"), std::string::npos) << m_out;
  EXPECT_NE(m_out.find("#SBATCH --requeue\n"), std::string::npos) << m_out;
  EXPECT_NE(m_out.find("--shard \"${SLURM_ARRAY_TASK_ID}/2\" --skip-existing"), std::string::npos) << m_out;
  // Without Slurm installed, submitting is a clear error (the script is still written).
  if (std::system("command -v sbatch >/dev/null 2>&1") != 0) {
    EXPECT_EQ(run("batch " + manifest + " --slurm -o " + path("out2")), 2);
    EXPECT_TRUE(fs::exists(path("out2/slurm/manifest.sbatch")));
  }
}

TEST_F(Batch, MetricsAgainstTheReferenceMatchCompare) {
  const std::string ref = path("ref.exr");
  ASSERT_EQ(run("render " + test::sourceDir() + "/data/scenes/cornell-box.json --res 12x12 --spp 64 -q -o " + ref), 0);
  const std::string manifest = writeManifest(gridManifest(ref));
  ASSERT_EQ(run("batch " + manifest + " -j 2 -t 1 -q -o " + path("out")), 0);
  const nlohmann::json t = readJson(path("out/results.json"));
  const Image reference = readImage(ref);
  for (const nlohmann::json& r : t["rows"]) {
    const ImageMetrics m = compareImages(readImage(path("out/" + r["name"].get<std::string>() + ".exr")), reference);
    EXPECT_NEAR(r["metrics"]["relmse"].get<double>(), m.relMse, 1e-12 * (1.0 + m.relMse));
    EXPECT_NEAR(r["metrics"]["psnr_srgb8"].get<double>(), m.psnrSrgb8, 1e-9);
  }
  // Metrics that cannot be computed (the reference is 12x12, the job 8x8) fail the job.
  nlohmann::json wrongSize = gridManifest(ref);
  wrongSize["defaults"]["res"] = "8x8";
  EXPECT_EQ(run("batch " + writeManifest(wrongSize, "wrong.json") + " -t 1 -q -o " + path("wrong")), 1);
  for (const nlohmann::json& r : readJson(path("wrong/results.json"))["rows"]) {
    EXPECT_EQ(r["status"], "failed") << r["name"];
    EXPECT_NE(r["error"].get<std::string>().find("size mismatch"), std::string::npos) << r["error"];
  }
}

TEST_F(Batch, MemoryBudgetFailsTheJobNotTheBatch) {
  nlohmann::json m = gridManifest();
  m.erase("grid");
  // Marched cones: the field holds every photon (with the default gather = "hit" it holds only
  // caustic ones, and level 9 fits).
  m["jobs"].push_back(
      {{"name", "big"}, {"method", "voxcone"}, {"options", {{"level", 9}, {"photons", 200000}, {"gather", "march"}}}});
  const std::string manifest = writeManifest(m);
  // The executable and its libraries alone take ~130 MB; level 9 needs more than 200 MB.
  EXPECT_EQ(run("batch " + manifest + " --memory-budget-mb 200 -t 1 -q -o " + path("out")), 1);
  const nlohmann::json t = readJson(path("out/results.json"));
  EXPECT_EQ(t["rows"][0]["status"], "ok");
  EXPECT_EQ(t["rows"][1]["status"], "failed");
  EXPECT_NE(t["rows"][1]["error"].get<std::string>().find("memory"), std::string::npos) << t["rows"][1];
  EXPECT_FALSE(fs::exists(path("out/big.exr")));
}

TEST_F(Batch, BadManifestsAreOneLineErrors) {
  for (const std::string bad : {R"({"jobs": [{"scene": "a.json", "sp": 4}]})", R"({"grid": {"spp": []}})",
                                R"({"jobs": [{"spp": 4}]})", R"({"jobs": [{"name": "x/y", "scene": "a.json"}]})",
                                R"({"jobs": [{"scene": "a.json"}, {"scene": "a.json"}]})", R"({"jobz": []})", "not json",
                                // A reference that is not there: refused before any job runs.
                                R"({"reference": "missing.exr", "jobs": [{"scene": "a.json"}]})"}) {
    std::ofstream(path("bad.json")) << bad;
    EXPECT_EQ(run("batch " + path("bad.json") + " --dry-run"), 2) << bad;
  }
}

}  // namespace
}  // namespace voxcone

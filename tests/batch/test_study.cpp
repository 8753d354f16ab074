// The study layer without the executable: Pareto fronts and the log-log interpolation on them
// against hand-computed values, the levels x photons manifest, and a sweep table from batch rows.

#include "voxcone/batch/study.h"

#include <gtest/gtest.h>

#include <cmath>

namespace voxcone {
namespace {

TEST(StudyLayer, ParetoFrontKeepsThePointsNothingBeats) {
  // (time, error): (1, 5) (2, 3) (3, 4) (4, 1) (2, 6) -> front (1, 5) (2, 3) (4, 1).
  const std::vector<std::pair<double, double>> pts = {{1, 5}, {2, 3}, {3, 4}, {4, 1}, {2, 6}};
  EXPECT_EQ(paretoFront(pts), (std::vector<size_t>{0, 1, 3}));
  EXPECT_TRUE(paretoFront({}).empty());
  // Equal times: only the lower error.
  EXPECT_EQ(paretoFront({{1, 2}, {1, 1}}), (std::vector<size_t>{1}));
}

TEST(StudyLayer, OnFrontIsLogLogLinear) {
  const std::vector<std::pair<double, double>> front = {{1, 8}, {4, 2}};
  // Halfway in log time (t = 2) is halfway in log error: sqrt(8 * 2) = 4.
  EXPECT_NEAR(onFront(front, 2.0), 4.0, 1e-12);
  EXPECT_NEAR(onFront(front, 1.0), 8.0, 1e-12);
  EXPECT_NEAR(onFront(front, 4.0), 2.0, 1e-12);
  EXPECT_TRUE(std::isnan(onFront(front, 0.5)));
  EXPECT_TRUE(std::isnan(onFront(front, 5.0)));
}

TEST(StudyLayer, LevelsTimesPhotonsIsAGridOfTwentyJobs) {
  SweepSettings s;
  s.kind = "levels";
  s.scenePath = "/scenes/box.json";
  s.referencePath = "/refs/box.exr";
  s.resolution = "16x16";
  s.photons = {2000, 5000, 10000, 20000};
  nlohmann::json m = sweepManifest(s);
  EXPECT_EQ(m["reference"], "/refs/box.exr");
  m.erase("reference");  // expanding checks that a reference exists
  const std::vector<Job> jobs = expandManifest(m, "/");
  ASSERT_EQ(jobs.size(), 20u);
  EXPECT_EQ(jobs[0].spec["options"]["level"], 5);
  EXPECT_EQ(jobs[0].spec["options"]["photons"], 2000);
  EXPECT_EQ(jobs[1].spec["options"]["photons"], 5000);  // photons vary fastest
  EXPECT_EQ(jobs[19].spec["options"]["level"], 9);
  EXPECT_EQ(jobs[19].spec["options"]["photons"], 20000);
  EXPECT_EQ(jobs[0].spec["res"], "16x16");
  // Without photon counts: the five levels at the scene's photons.
  s.photons.clear();
  m = sweepManifest(s);
  m.erase("reference");
  EXPECT_EQ(expandManifest(m, "/").size(), 5u);
}

/// A batch result row as runJobs gives it: a 4-spp render of `method` that took `seconds` to
/// `relmse`.
nlohmann::json sweepRow(const std::string& name, const std::string& method, double seconds, double relmse) {
  return nlohmann::json{{"name", name},
                        {"status", "ok"},
                        {"method", method},
                        {"spp", 4},
                        {"options", nlohmann::json::object()},
                        {"timings", {{"total_seconds", seconds}}},
                        {"metrics", {{"relmse", relmse}, {"mse", relmse}, {"psnr_srgb8", 30.0}}},
                        {"peak_rss_bytes", 1e8},
                        {"integrator", {{"photons", 1000}, {"level", 6}}}};
}

TEST(StudyLayer, SweepTableKeepsSuccessfulRendersAndComparesWithPathsFront) {
  const auto row = sweepRow;
  nlohmann::json rows = nlohmann::json::array();
  rows.push_back(row("p1", "path", 1.0, 0.08));
  rows.push_back(row("p4", "path", 4.0, 0.02));
  rows.push_back(row("v1", "voxcone", 2.0, 0.01));
  rows.push_back(row("v2", "voxcone", 3.0, 0.02));  // beaten by v1
  nlohmann::json failed = row("bad", "voxcone", 0.1, 0.0);
  failed["status"] = "failed";
  rows.push_back(failed);
  const nlohmann::json t = sweepTable(rows);
  ASSERT_EQ(t["rows"].size(), 4u);  // the failed render is left out
  EXPECT_TRUE(t["rows"][2]["pareto"].get<bool>());
  EXPECT_FALSE(t["rows"][3]["pareto"].get<bool>());
  // v1 against path's front: at 2 s path's relMSE is sqrt(0.08 * 0.02) = 0.04 (log-log halfway);
  // path reaches 0.01 nowhere on its front (below its last point): null.
  ASSERT_EQ(t["comparisons"].size(), 1u);
  const nlohmann::json& c = t["comparisons"][0];
  EXPECT_EQ(c["name"], "v1");
  EXPECT_NEAR(c["path_relmse_at_equal_time"].get<double>(), 0.04, 1e-12);
  EXPECT_TRUE(c["path_seconds_at_equal_relmse"].is_null());
  EXPECT_EQ(c["against"], "path");
}

TEST(StudyLayer, DenoisedRendersAreFrontsOfTheirOwnRacedAgainstDenoisedPath) {
  auto row = [](const std::string& name, const std::string& method, bool denoise, double seconds, double relmse) {
    nlohmann::json r = sweepRow(name, method, seconds, relmse);
    if (denoise) r["denoise"] = true;
    return r;
  };
  nlohmann::json rows = nlohmann::json::array();
  rows.push_back(row("p1", "path", false, 1.0, 0.08));
  rows.push_back(row("p4", "path", false, 4.0, 0.02));
  rows.push_back(row("pd1", "path", true, 1.0, 0.004));
  rows.push_back(row("pd4", "path", true, 4.0, 0.001));
  rows.push_back(row("vd", "voxcone", true, 2.0, 0.002));
  const nlohmann::json t = sweepTable(rows);
  EXPECT_EQ(t["rows"][2]["method"], "path+denoise");
  EXPECT_EQ(t["rows"][4]["method"], "voxcone+denoise");
  // One comparison (neither path front is compared with itself): against denoised path, whose
  // relMSE at 2 s is sqrt(0.004 * 0.001) = 0.002 (log-log halfway), the time at 0.002 is 2 s.
  ASSERT_EQ(t["comparisons"].size(), 1u);
  const nlohmann::json& c = t["comparisons"][0];
  EXPECT_EQ(c["against"], "path+denoise");
  EXPECT_NEAR(c["path_relmse_at_equal_time"].get<double>(), 0.002, 1e-12);
  EXPECT_NEAR(c["path_seconds_at_equal_relmse"].get<double>(), 2.0, 1e-9);
  EXPECT_NEAR(c["speedup_vs_path"].get<double>(), 1.0, 1e-9);
  // The batch runs it as render --denoise, and names it so.
  Job job;
  job.spec = {{"scene", "/s/box.json"}, {"method", "path"}, {"denoise", true}, {"options", nlohmann::json::object()}};
  EXPECT_NE(jobName(job.spec).find("_denoise"), std::string::npos);
}

}  // namespace
}  // namespace voxcone

// `voxcone study speed-accuracy / photons / levels --quick` and tools/plot_study.py: the tables,
// speed-accuracy's Pareto fronts checked by brute force, and charts that plot the studies' numbers.

#include "../support/temp_dir.h"
#include "../support/test_scenes.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <sys/wait.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <tuple>

namespace voxcone {
namespace {

class StudySweeps : public test::TempDirTest {};

TEST_F(StudySweeps, QuickStudyTablesFrontsAndChart) {
  const std::string cli = VOXCONE_CLI_PATH;
  if (!std::filesystem::exists(cli)) GTEST_SKIP() << "no CLI at " << cli;
  const std::string scene = test::sourceDir() + "/data/scenes/cornell-box.json";
  ASSERT_EQ(std::system((cli + " render " + scene + " --res 16x16 --spp 64 -q -o " + path("ref") + " > /dev/null").c_str()), 0);
  const std::string cmd = cli + " study speed-accuracy " + scene + " --reference " + path("ref.exr") +
                          " --quick --res 16x16 -j 2 -t 1 -o " + path("study") + " > " + path("out.txt") + " 2>&1";
  const int status = std::system(cmd.c_str());
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << std::ifstream(path("out.txt")).rdbuf();
  std::ifstream f(path("study/speed-accuracy.json"));
  const nlohmann::json study = nlohmann::json::parse(f);
  const nlohmann::json& rows = study["rows"];
  // path 3 spp, pm 2 photon counts, voxcone 2 levels x 2 cone counts, voxcone --target-error;
  // with the denoiser's weights fetched, path+denoise at 2 spp and voxcone+denoise.
  const bool denoise = std::filesystem::exists(test::sourceDir() + "/data/models/oidn/rt_hdr_alb_nrm.tza");
  ASSERT_EQ(rows.size(), denoise ? 13u : 10u);

  // Pareto flags by brute force: a render is on its method's front when no other render of the
  // method is at least as fast and more accurate, or faster and at least as accurate.
  int fronts = 0;
  for (const nlohmann::json& a : rows) {
    bool dominated = false;
    for (const nlohmann::json& b : rows) {
      if (&a == &b || a["method"] != b["method"]) continue;
      const double ta = a["seconds"], tb = b["seconds"], ea = a["relmse"], eb = b["relmse"];
      dominated = dominated || (tb <= ta && eb < ea) || (tb < ta && eb <= ea);
    }
    EXPECT_EQ(a["pareto"].get<bool>(), !dominated) << a["name"];
    fronts += a["pareto"].get<bool>();
  }
  EXPECT_GE(fronts, 3);  // at least one per method
  // One comparison per pm / voxcone front point; where defined, path's time at equal error lies
  // within path's front (denoised path's for a denoised method).
  std::map<std::string, std::pair<double, double>> pathSpan;
  for (const nlohmann::json& r : rows)
    if ((r["method"] == "path" || r["method"] == "path+denoise") && r["pareto"].get<bool>()) {
      auto& [lo, hi] = pathSpan.try_emplace(r["method"], 1e30, 0.0).first->second;
      lo = std::min(lo, r["seconds"].get<double>());
      hi = std::max(hi, r["seconds"].get<double>());
    }
  int nonPathFront = 0;
  for (const nlohmann::json& r : rows)
    nonPathFront += (r["pareto"].get<bool>() && r["method"] != "path" && r["method"] != "path+denoise") ||
                    r["method"] == "voxcone-auto";
  // The render that chose its own settings is compared with voxcone's front too.
  int chosen = 0;
  for (const nlohmann::json& c : study["comparisons"])
    if (c["method"] == "voxcone-auto") {
      ++chosen;
      EXPECT_TRUE(c.contains("voxcone_front_relmse_at_equal_time"));
      EXPECT_GT(c["predicted_relmse"].get<double>(), 0.0);
    }
  EXPECT_EQ(chosen, 1);
  ASSERT_EQ(study["comparisons"].size(), size_t(nonPathFront));
  for (const nlohmann::json& c : study["comparisons"]) {
    EXPECT_EQ(c["against"], c["method"] == "voxcone+denoise" ? "path+denoise" : "path");
    if (!c["path_seconds_at_equal_relmse"].is_null()) {
      const auto [lo, hi] = pathSpan.at(c["against"]);
      EXPECT_GE(c["path_seconds_at_equal_relmse"].get<double>(), lo * (1 - 1e-9));
      EXPECT_LE(c["path_seconds_at_equal_relmse"].get<double>(), hi * (1 + 1e-9));
    }
  }

  // The chart exists and plots exactly the study's numbers.
  EXPECT_GT(std::filesystem::file_size(path("study/speed-accuracy.png")), 10000u);
  EXPECT_GT(std::filesystem::file_size(path("study/speed-accuracy.svg")), 10000u);
  std::ifstream p(path("study/speed-accuracy.plotted.json"));
  const nlohmann::json plotted = nlohmann::json::parse(p);
  std::map<std::string, size_t> seen;
  for (const nlohmann::json& r : rows) {
    const std::string m = r["method"];
    const size_t k = seen[m]++;
    EXPECT_DOUBLE_EQ(plotted[m]["seconds"][k].get<double>(), r["seconds"].get<double>());
    EXPECT_DOUBLE_EQ(plotted[m]["relmse"][k].get<double>(), r["relmse"].get<double>());
  }
  // The CSV: a header and one line per render.
  std::ifstream csv(path("study/speed-accuracy.csv"));
  size_t lines = 0;
  for (std::string l; std::getline(csv, l);) ++lines;
  EXPECT_EQ(lines, rows.size() + 1);
}

TEST_F(StudySweeps, QuickPhotonsAndLevelsStudiesPlotTheirRows) {
  const std::string cli = VOXCONE_CLI_PATH;
  if (!std::filesystem::exists(cli)) GTEST_SKIP() << "no CLI at " << cli;
  const std::string scene = test::sourceDir() + "/data/scenes/cornell-box.json";
  ASSERT_EQ(std::system((cli + " render " + scene + " --res 16x16 --spp 64 -q -o " + path("ref") + " > /dev/null").c_str()), 0);
  // (study, x key, rows: pm and voxcone at 1000 and 4000 photons; voxcone at levels 3, 4, 5)
  for (const auto& [kind, x, expected] : {std::tuple<std::string, std::string, size_t>{"photons", "photons", 4},
                                          {"levels", "level", 3}}) {
    // levels without --res: the reference's size is the default.
    const std::string cmd = cli + " study " + kind + " " + scene + " --reference " + path("ref.exr") + " --quick" +
                            (kind == "levels" ? "" : " --res 16x16") + " -j 2 -t 1 -o " + path(kind) + " > /dev/null 2>&1";
    ASSERT_EQ(std::system(cmd.c_str()), 0) << kind;
    std::ifstream f(path(kind + "/" + kind + ".json"));
    const nlohmann::json study = nlohmann::json::parse(f);
    ASSERT_EQ(study["rows"].size(), expected) << kind;
    EXPECT_GT(std::filesystem::file_size(path(kind + "/" + kind + ".png")), 10000u);
    std::ifstream p(path(kind + "/" + kind + ".plotted.json"));
    const nlohmann::json plotted = nlohmann::json::parse(p);
    // Each row is plotted at its x with its MSE and relMSE (series sorted by x per method).
    for (const nlohmann::json& r : study["rows"]) {
      const nlohmann::json& m = plotted[r["method"].get<std::string>()];
      bool found = false;
      for (size_t k = 0; k < m[x].size(); ++k)
        found = found || (m[x][k] == r[x] && m["mse"][k].get<double>() == r["mse"].get<double>() &&
                          m["relmse"][k].get<double>() == r["relmse"].get<double>());
      EXPECT_TRUE(found) << kind << " " << r["name"];
      EXPECT_FALSE(r[x].is_null()) << kind << " " << r["name"];  // taken from the render's own settings
    }
  }
  // Another size than the reference's: refused before any job runs, nothing rendered.
  const std::string bad = cli + " study levels " + scene + " --reference " + path("ref.exr") +
                          " --quick --res 32x32 -t 1 -o " + path("mismatch") + " > /dev/null 2>&1";
  EXPECT_EQ(std::system(bad.c_str()), 2 << 8);
  EXPECT_FALSE(std::filesystem::exists(path("mismatch/runs")));
}

}  // namespace
}  // namespace voxcone

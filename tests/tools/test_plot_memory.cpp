// tools/plot_memory.py: the chart files exist and the plotted numbers are the study's.

#include "../support/temp_dir.h"
#include "../support/test_scenes.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstdlib>
#include <filesystem>
#include <fstream>

namespace voxcone {
namespace {

class PlotMemory : public test::TempDirTest {};

TEST_F(PlotMemory, ChartFilesExistAndPlottedNumbersMatchTheStudy) {
  const nlohmann::json study = {
      {"study", "memory"},
      {"scene", "data/scenes/cornell-dragon.json"},
      {"photons", 1000},
      {"rows",
       {{{"level", 6}, {"total_bytes", 1.5e6}, {"peak_rss_bytes", 9e7}, {"voxelize_seconds", 0.1},
         {"inject_seconds", 0.2}, {"mip_seconds", 0.01}, {"bytes", {{"topology", 1e6}, {"radiance", 5e5}}}},
        {{"level", 7}, {"total_bytes", 4.25e6}, {"peak_rss_bytes", 1e8}, {"voxelize_seconds", 0.3},
         {"inject_seconds", 0.4}, {"mip_seconds", 0.02}, {"bytes", {{"topology", 3e6}, {"radiance", 1.25e6}}}},
        {{"level", 8}, {"error", "out of memory"}}}}};
  std::ofstream(path("study.json")) << study.dump();
  const std::string cmd = "/usr/bin/python3 " + test::sourceDir() + "/tools/plot_memory.py " + path("study.json") + " " +
                          path("memory") + " > /dev/null";
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  EXPECT_GT(std::filesystem::file_size(path("memory.png")), 10000u);
  EXPECT_GT(std::filesystem::file_size(path("memory.svg")), 10000u);
  std::ifstream f(path("memory.plotted.json"));
  const nlohmann::json s = nlohmann::json::parse(f);
  EXPECT_EQ(s["levels"], nlohmann::json({6, 7}));
  EXPECT_DOUBLE_EQ(s["total_mb"][0].get<double>(), 1.5);
  EXPECT_DOUBLE_EQ(s["total_mb"][1].get<double>(), 4.25);
  EXPECT_DOUBLE_EQ(s["radiance_mb"][1].get<double>(), 1.25);
  EXPECT_DOUBLE_EQ(s["inject_s"][1].get<double>(), 0.4);
  EXPECT_EQ(s["failed_levels"], nlohmann::json({8}));
  // The reference study's figures for the same dragon are drawn beside ours.
  EXPECT_DOUBLE_EQ(s["reference_mb"][2].get<double>(), 1469.22);
}

}  // namespace
}  // namespace voxcone

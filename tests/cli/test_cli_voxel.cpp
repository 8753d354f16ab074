// `voxcone voxelize` and `voxcone study memory` end to end on the cornell box.

#include "../support/temp_dir.h"
#include "../support/test_scenes.h"
#include "voxcone/voxel/voxel_field.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>

namespace voxcone {
namespace {

class CliVoxel : public test::TempDirTest {
protected:
  int run(const std::string& args, const std::string& stdoutFile) const {
    const std::string cmd = std::string(VOXCONE_CLI_PATH) + " " + args + " > " + stdoutFile + " 2>/dev/null";
    return std::system(cmd.c_str());
  }
  std::string scene() const { return test::sourceDir() + "/data/scenes/cornell-box.json"; }
};

TEST_F(CliVoxel, VoxelizePrintsJsonTableAndWritesVdb) {
  ASSERT_EQ(run("voxelize " + scene() + " --level 6 --coarsest-level 3 --photons 20000 --json -o " + path("g.vdb"),
                path("out.json")),
            0);
  std::ifstream f(path("out.json"));
  const nlohmann::json j = nlohmann::json::parse(f);
  EXPECT_EQ(j["level"], 6);
  EXPECT_NEAR(j["voxel_size"].get<double>(), 559.2 * (1.0 + 2.0 * kDefaultFieldPadding) / 64.0, 0.01);
  EXPECT_GT(j["total_bytes"].get<double>(), 0.0);
  // One row per grid and level, levels 6..3 for each grid kind.
  int finestTopology = 0;
  for (const auto& g : j["grids"])
    if (g["grid"] == "topology" && g["level"] == 6) finestTopology = g["active_voxels"].get<int>();
  EXPECT_GT(finestTopology, 1000);
  EXPECT_GT(std::filesystem::file_size(path("g.vdb")), 1000u);
  // Debian's vdb_print (libopenvdb-tools) reads the file.
  if (std::system("command -v vdb_print > /dev/null") == 0) {
    EXPECT_EQ(std::system(("vdb_print " + path("g.vdb") + " > " + path("print.txt")).c_str()), 0);
    std::ifstream p(path("print.txt"));
    const std::string text((std::istreambuf_iterator<char>(p)), std::istreambuf_iterator<char>());
    EXPECT_NE(text.find("coverage_L6"), std::string::npos) << text;
    EXPECT_NE(text.find("radiance_L3"), std::string::npos) << text;
  }
}

TEST_F(CliVoxel, VoxelizeBadInputFailsWithoutOutput) {
  EXPECT_NE(run("voxelize " + scene() + " --level 6 --coarsest-level 7 -o " + path("a.vdb"), path("o.txt")), 0);
  EXPECT_NE(run("voxelize /nonexistent.json --level 6 -o " + path("b.vdb"), path("o.txt")), 0);
  EXPECT_NE(run("voxelize " + scene() + " --level 6 -o /nonexistent-dir/c.vdb", path("o.txt")), 0);
  EXPECT_FALSE(std::filesystem::exists(path("a.vdb")));
  EXPECT_FALSE(std::filesystem::exists(path("b.vdb")));
}

TEST_F(CliVoxel, StudyMemoryWritesCsvJsonAndChart) {
  ASSERT_EQ(run("study memory " + scene() + " --levels 4..5 --photons 5000 -o " + path("study"), path("o.txt")), 0);
  std::ifstream f(path("study/memory.json"));
  const nlohmann::json j = nlohmann::json::parse(f);
  ASSERT_EQ(j["rows"].size(), 2u);
  for (int i = 0; i < 2; ++i) {
    EXPECT_EQ(j["rows"][i]["level"], 4 + i);
    EXPECT_GT(j["rows"][i]["total_bytes"].get<double>(), 0.0);
    EXPECT_GT(j["rows"][i]["peak_rss_bytes"].get<double>(), 0.0);
  }
  // More voxels at the finer level.
  EXPECT_GT(j["rows"][1]["active_voxels"].get<double>(), j["rows"][0]["active_voxels"].get<double>());
  EXPECT_TRUE(std::filesystem::exists(path("study/memory.csv")));
  EXPECT_TRUE(std::filesystem::exists(path("study/memory.png")));
  EXPECT_TRUE(std::filesystem::exists(path("study/memory.svg")));
}

}  // namespace
}  // namespace voxcone

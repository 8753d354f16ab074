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

TEST_F(CliVoxel, RenderWithAFieldReadBack) {
  // A field written by voxelize renders as the render's own field does: the same photons (the
  // render's seed and counts), so the same image to the bit. (A field read back has no photons:
  // its cones read the field at their hits, as hit_radiance = field does.)
  ASSERT_EQ(run("voxelize " + scene() + " --level 5 --photons 10000 -q -o " + path("f.vdb"), path("o.txt")), 0);
  const std::string common = " --res 32x32 --spp 2 -t 2 -q --max-depth 16 ";
  ASSERT_EQ(run("render " + scene() + common + "--field " + path("f.vdb") + " -o " + path("a"), path("o.txt")), 0);
  const std::string options = "'{\"level\": 5, \"coarsest_level\": 2, \"photons\": 10000, \"hit_radiance\": \"field\"}'";
  ASSERT_EQ(run("render " + scene() + common + "--options " + options + " -o " + path("b"), path("o.txt")), 0);
  std::ifstream side(path("a.json"));
  const nlohmann::json j = nlohmann::json::parse(side);
  EXPECT_EQ(j["settings"]["integrator"]["field"], path("f.vdb"));
  EXPECT_EQ(j["settings"]["integrator"]["level"], 5);
  EXPECT_TRUE(j["stats"]["integrator"].contains("field_read_seconds"));
  ASSERT_EQ(run("compare " + path("a.exr") + " " + path("b.exr") + " --json", path("cmp.json")), 0);
  std::ifstream cmp(path("cmp.json"));
  EXPECT_EQ(nlohmann::json::parse(cmp)["relmse"].get<double>(), 0.0);

  // Refused, with nothing written: another scene, a field with options it fixes, with passes
  // that trace new photons, a missing file, another method.
  const std::string other = test::sourceDir() + "/data/scenes/thin-wall.json";
  EXPECT_EQ(run("render " + other + common + "--field " + path("f.vdb") + " -o " + path("c"), path("o.txt")), 2 << 8);
  EXPECT_EQ(run("render " + scene() + common + "--field " + path("f.vdb") + " --options '{\"level\": 6}' -o " + path("c"),
                path("o.txt")),
            2 << 8);
  EXPECT_EQ(run("render " + scene() + common + "--field " + path("f.vdb") + " --target-error 0.01 -o " + path("c"),
                path("o.txt")),
            2 << 8);
  EXPECT_EQ(run("render " + scene() + common + "--field " + path("missing.vdb") + " -o " + path("c"), path("o.txt")), 2 << 8);
  EXPECT_EQ(run("render " + scene() + common + "--method path --field " + path("f.vdb") + " -o " + path("c"), path("o.txt")),
            2 << 8);
  EXPECT_FALSE(std::filesystem::exists(path("c.exr")));
}

TEST_F(CliVoxel, MemoryBudgetRefusesBeforeVoxelizing) {
  // Level 10 of the cornell box needs tens of MB: refused at 5 MB with the level that fits,
  // and nothing written; without a budget (0) it is voxelized.
  const std::string err = path("err.txt");
  const std::string cmd = std::string(VOXCONE_CLI_PATH) + " voxelize " + scene() +
                          " --level 10 --photons 1000 -q --memory-budget-mb 5 -o " + path("big.vdb") + " 2> " + err;
  EXPECT_EQ(std::system(cmd.c_str()), 2 << 8);
  std::ifstream e(err);
  const std::string text((std::istreambuf_iterator<char>(e)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("voxel level 10 needs about"), std::string::npos) << text;
  EXPECT_NE(text.find("memory budget of 5 MB"), std::string::npos) << text;
  EXPECT_NE(text.find("would fit"), std::string::npos) << text;
  EXPECT_FALSE(std::filesystem::exists(path("big.vdb")));
  EXPECT_EQ(run("render " + scene() + " --res 16x16 --spp 1 -q --memory-budget-mb 1 --options '{\"level\": 9}' -o " +
                    path("r"),
                path("o.txt")),
            2 << 8);
  EXPECT_EQ(run("voxelize " + scene() + " --level 6 --photons 1000 -q --memory-budget-mb 0", path("o.txt")), 0);
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

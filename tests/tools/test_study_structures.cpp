// Generated knot meshes, `voxcone study structures --quick` and `study scaling --quick`: tables
// whose ratios are the quotients of their own times, the same image from every structure, and
// charts that plot the studies' numbers.

#include "voxcone/accel/accel.h"
#include "voxcone/core/error.h"
#include "voxcone/scene/generate.h"

#include "../support/temp_dir.h"
#include "../support/test_scenes.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <utility>

namespace voxcone {
namespace {

class StudyStructures : public test::TempDirTest {};

TEST_F(StudyStructures, KnotMeshIsClosedNonDegenerateAndRoundTripsThroughPly) {
  const TriangleMesh mesh = makeKnotMesh(10000);
  // 2 x segments x sides with segments = 8 sides: as near 10000 as the grid allows.
  EXPECT_NEAR(double(mesh.triangles.size()), 10000.0, 300.0);
  EXPECT_EQ(mesh.triangles.size(), 2 * mesh.positions.size());  // a torus: V - E + F = 0
  // Closed: every edge is shared by exactly two triangles, once in each direction.
  std::map<std::pair<uint32_t, uint32_t>, int> directed;
  for (const UVec3& t : mesh.triangles) {
    for (int k = 0; k < 3; ++k) ++directed[{t[k], t[(k + 1) % 3]}];
    const Vec3 e1 = mesh.positions[t.y] - mesh.positions[t.x], e2 = mesh.positions[t.z] - mesh.positions[t.x];
    EXPECT_GT(glm::length(glm::cross(e1, e2)), 1e-6f);
  }
  for (const auto& [edge, count] : directed) {
    EXPECT_EQ(count, 1);
    EXPECT_EQ(directed.count({edge.second, edge.first}), 1u);
  }
  const Bounds3 b = mesh.bounds();
  EXPECT_NEAR(b.hi.x - b.lo.x, 6.07f, 0.1f);
  EXPECT_NEAR(b.hi.y - b.lo.y, 6.34f, 0.1f);
  EXPECT_NEAR(b.hi.z - b.lo.z, 2.68f, 0.1f);

  writePly(path("knot.ply"), mesh);
  const TriangleMesh back = loadPly(path("knot.ply"));
  ASSERT_EQ(back.positions.size(), mesh.positions.size());
  ASSERT_EQ(back.triangles.size(), mesh.triangles.size());
  EXPECT_EQ(back.positions, mesh.positions);
  EXPECT_EQ(back.triangles, mesh.triangles);
  EXPECT_THROW(makeKnotMesh(10), SettingsError);
}

TEST_F(StudyStructures, GenerateMeshCommandRejectsBadOutput) {
  const std::string cli = VOXCONE_CLI_PATH;
  if (!std::filesystem::exists(cli)) GTEST_SKIP() << "no CLI at " << cli;
  EXPECT_NE(std::system((cli + " generate-mesh --triangles 1000 -o " + path("knot.obj") + " 2>/dev/null").c_str()), 0);
  EXPECT_FALSE(std::filesystem::exists(path("knot.obj")));
  EXPECT_NE(std::system((cli + " generate-mesh --triangles 5 -o " + path("small.ply") + " 2>/dev/null").c_str()), 0);
  EXPECT_FALSE(std::filesystem::exists(path("small.ply")));
  EXPECT_EQ(std::system((cli + " generate-mesh --triangles 1000 -o " + path("ok.ply") + " > /dev/null").c_str()), 0);
  EXPECT_EQ(loadPly(path("ok.ply")).triangles.size(), 1008u);  // 2 x 63 x 8
}

nlohmann::json readJson(const std::string& p) {
  std::ifstream f(p);
  return nlohmann::json::parse(f);
}

size_t lineCount(const std::string& p) {
  std::ifstream f(p);
  size_t n = 0;
  for (std::string l; std::getline(f, l);) ++n;
  return n;
}

TEST_F(StudyStructures, QuickStructuresStudyComparesEveryStructureOnTheSameImage) {
  const std::string cli = VOXCONE_CLI_PATH;
  if (!std::filesystem::exists(cli)) GTEST_SKIP() << "no CLI at " << cli;
  const std::string cmd = cli + " study structures --quick -t 1 -o " + path("s") + " > " + path("out.txt") + " 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << std::ifstream(path("out.txt")).rdbuf();
  const nlohmann::json study = readJson(path("s/structures.json"));
  const nlohmann::json& rows = study["rows"];
  const std::vector<std::string>& kinds = accelKinds();  // hbvh, bvh, kdtree (and embree where built)
  ASSERT_EQ(rows.size(), 2 * kinds.size());              // two generated meshes x every structure
  std::map<std::string, nlohmann::json> hbvh;
  for (const nlohmann::json& r : rows)
    if (r["accel"] == "hbvh") hbvh[r["mesh"]] = r;
  ASSERT_EQ(hbvh.size(), 2u);
  std::set<std::string> accels;
  for (const nlohmann::json& r : rows) {
    accels.insert(r["accel"].get<std::string>());
    const nlohmann::json& h = hbvh[r["mesh"]];
    EXPECT_EQ(r["triangles"], h["triangles"]);
    // Ratios are the quotients of the rows' own numbers.
    EXPECT_NEAR(r["render_vs_hbvh"].get<double>(), r["render_s"].get<double>() / h["render_s"].get<double>(), 1e-9);
    EXPECT_NEAR(r["build_vs_hbvh"].get<double>(), r["build_s"].get<double>() / h["build_s"].get<double>(), 1e-9);
    EXPECT_NEAR(r["memory_vs_hbvh"].get<double>(), r["accel_mb"].get<double>() / h["accel_mb"].get<double>(), 1e-9);
    EXPECT_EQ(r["accel_stats"]["kind"], r["accel"]);
    // The same image: every structure finds the same closest hits; a pixel may differ where a
    // sample passes exactly through an edge shared by two triangles. Embree's own triangle test
    // rounds hit points differently, so nearly every pixel differs in its last bits.
    if (r["accel"] != "embree") {
      EXPECT_LE(r["pixels_differing_from_hbvh"].get<int>(), 24 * 24 / 100) << r["mesh"] << " " << r["accel"];
    }
    EXPECT_LT(r["relmse_vs_hbvh"].get<double>(), 1e-3);
    if (r["accel"] == "kdtree") {
      EXPECT_GE(r["accel_stats"]["references"].get<double>(), r["triangles"].get<double>() - 12);
    }
  }
  EXPECT_EQ(accels, (std::set<std::string>(kinds.begin(), kinds.end())));
  EXPECT_EQ(lineCount(path("s/structures.csv")), rows.size() + 1);
  EXPECT_GT(std::filesystem::file_size(path("s/structures.png")), 10000u);
  const nlohmann::json plotted = readJson(path("s/structures.plotted.json"));
  for (const nlohmann::json& r : rows) {
    const nlohmann::json& meshes = plotted["meshes"];
    const size_t k = std::find(meshes.begin(), meshes.end(), r["mesh"]) - meshes.begin();
    ASSERT_LT(k, meshes.size());
    const nlohmann::json& a = plotted[r["accel"].get<std::string>()];
    EXPECT_DOUBLE_EQ(a["render_s"][k].get<double>(), r["render_s"].get<double>());
    EXPECT_DOUBLE_EQ(a["build_s"][k].get<double>(), r["build_s"].get<double>());
    EXPECT_DOUBLE_EQ(a["accel_mb"][k].get<double>(), r["accel_mb"].get<double>());
  }
}

TEST_F(StudyStructures, QuickScalingStudyIsDeterministicAcrossThreadsAndFitsExponents) {
  const std::string cli = VOXCONE_CLI_PATH;
  if (!std::filesystem::exists(cli)) GTEST_SKIP() << "no CLI at " << cli;
  const std::string scene = test::sourceDir() + "/data/scenes/cornell-box.json";
  const std::string cmd = cli + " study scaling " + scene + " --quick -t 1 -o " + path("c") + " > " + path("out.txt") + " 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << std::ifstream(path("out.txt")).rdbuf();
  const nlohmann::json study = readJson(path("c/scaling.json"));
  ASSERT_EQ(study["threads"].size(), 4u);    // path and voxcone at 1 and 2 threads
  ASSERT_EQ(study["triangles"].size(), 4u);  // path and voxcone at 1000 and 4000 triangles
  for (const nlohmann::json& r : study["threads"]) {
    // Results do not depend on the thread count.
    EXPECT_EQ(r["pixels_differing_from_1_thread"].get<int>(), 0) << r["method"] << " " << r["threads"];
    EXPECT_NEAR(r["efficiency"].get<double>(), r["speedup"].get<double>() / r["threads"].get<double>(), 1e-9);
    if (r["threads"] == 1) {
      EXPECT_DOUBLE_EQ(r["speedup"].get<double>(), 1.0);
    }
  }
  for (const nlohmann::json& r : study["triangles"]) {
    // The room's 12 triangles and the knot.
    EXPECT_GE(r["triangles"].get<int>(), r["requested_triangles"].get<int>());
    EXPECT_LE(r["triangles"].get<int>(), r["requested_triangles"].get<int>() + 100);
  }
  for (const char* m : {"path", "voxcone"}) EXPECT_TRUE(study["triangle_exponents"][m]["build"].is_number()) << m;
  EXPECT_EQ(lineCount(path("c/scaling-threads.csv")), 5u);
  EXPECT_EQ(lineCount(path("c/scaling-triangles.csv")), 5u);
  const nlohmann::json plotted = readJson(path("c/scaling.plotted.json"));
  for (const nlohmann::json& r : study["triangles"]) {
    const nlohmann::json& m = plotted["triangles"][r["method"].get<std::string>()];
    bool found = false;
    for (size_t k = 0; k < m["triangles"].size(); ++k)
      found = found || (m["triangles"][k] == r["triangles"] && m["render_s"][k] == r["render_s"] &&
                        m["build_s"][k] == r["build_s"]);
    EXPECT_TRUE(found) << r["method"] << " " << r["triangles"];
  }
}

}  // namespace
}  // namespace voxcone

/// \file test_obj.cpp
/// OBJ loader (tinyobjloader): materials from MTL, missing MTL, malformed faces, normals
/// de-indexed into per-vertex normals.

#include "voxcone/core/error.h"
#include "voxcone/scene/mesh.h"

#include <gtest/gtest.h>

#include "../support/mesh_errors.h"
#include "../support/temp_dir.h"

#include <filesystem>
#include <fstream>
#include <set>
#include <string>
#include <unistd.h>
#include <tuple>

namespace fs = std::filesystem;
using namespace voxcone;

namespace {

class ObjTest : public test::TempDirTest {
};

void expectMeshError(const std::string& path, const std::string& needle = "") {
  test::expectMeshError([](const std::string& p) { return loadObj(p); }, path, needle);
}

Vec3 faceNormal(const TriangleMesh& m, const UVec3& t) {
  return glm::normalize(
      glm::cross(m.positions[t.y] - m.positions[t.x], m.positions[t.z] - m.positions[t.x]));
}

}  // namespace

TEST_F(ObjTest, ShippedCubeWithMaterials) {
  const TriangleMesh m = loadObj(std::string(VOXCONE_SOURCE_DIR) + "/data/meshes/cube.obj");
  ASSERT_EQ(m.triangles.size(), 12u);
  ASSERT_EQ(m.materials.size(), 2u);
  const MeshMaterial& white = m.materials[0];
  const MeshMaterial& light = m.materials[1];
  EXPECT_EQ(white.name, "white");
  EXPECT_EQ(white.kd, Vec3(0.8f));
  EXPECT_EQ(white.ke, Vec3(0.0f));
  EXPECT_EQ(white.ns, 10.0f);
  EXPECT_FLOAT_EQ(white.ni, 1.5f);
  EXPECT_EQ(white.illum, 2);
  EXPECT_EQ(light.name, "light");
  EXPECT_EQ(light.kd, Vec3(0.0f));
  EXPECT_EQ(light.ke, Vec3(10.0f, 9.0f, 8.0f));
  EXPECT_EQ(light.illum, 0);

  // Ten white triangles, then the two emissive ones of the top face (y = 1).
  ASSERT_EQ(m.faceMaterial.size(), 12u);
  for (size_t i = 0; i < 12; ++i) {
    EXPECT_EQ(m.faceMaterial[i], i < 10 ? 0 : 1) << i;
    if (i >= 10) {
      for (int k = 0; k < 3; ++k) EXPECT_EQ(m.positions[m.triangles[i][k]].y, 1.0f);
    }
  }

  // Per-face normals: each of the 6 faces has its own 4 corners -> 24 vertices, and every
  // vertex normal equals its triangle's outward geometric normal.
  ASSERT_EQ(m.positions.size(), 24u);
  ASSERT_EQ(m.normals.size(), 24u);
  for (const UVec3& t : m.triangles) {
    const Vec3 n = faceNormal(m, t);
    const Vec3 toOut = (m.positions[t.x] + m.positions[t.y] + m.positions[t.z]) / 3.0f - Vec3(0.5f);
    EXPECT_GT(glm::dot(n, toOut), 0.0f);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(glm::dot(m.normals[t[k]], n), 1.0f, 1e-6f);
  }
  const Bounds3 b = m.bounds();
  EXPECT_EQ(b.lo, Vec3(0.0f));
  EXPECT_EQ(b.hi, Vec3(1.0f));
}

TEST_F(ObjTest, MissingMtlIsAnError) {
  const std::string path = write("nomtl.obj", "mtllib does_not_exist.mtl\nv 0 0 0\nv 1 0 0\n"
                                              "v 0 1 0\nusemtl red\nf 1 2 3\n");
  expectMeshError(path, "does_not_exist.mtl");
}

TEST_F(ObjTest, MalformedFilesThrow) {
  expectMeshError((m_dir / "missing.obj").string(), "cannot open");
  expectMeshError(write("oor.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n"), "out of");
  expectMeshError(write("oorquad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3 7\n"));
  expectMeshError(write("zero.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n"));
  expectMeshError(write("badn.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//4\n"),
                  "normal");
}

TEST_F(ObjTest, NormalsDeIndexed) {
  // Two triangles share the edge 2-3 (file indices). Position 2 is used with the same normal
  // by both (one vertex); position 3 with two different normals (two vertices).
  const std::string text =
      "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n"
      "vn 0 0 1\nvn 0 0.6 0.8\nvn 0.6 0 0.8\n"
      "f 1//1 2//1 3//2\n"
      "f 2//1 4//3 3//3\n";
  const TriangleMesh m = loadObj(write("n.obj", text));
  ASSERT_EQ(m.triangles.size(), 2u);
  ASSERT_EQ(m.positions.size(), 5u);  // (1,1) (2,1) (3,2) (4,3) (3,3)
  ASSERT_EQ(m.normals.size(), 5u);
  EXPECT_TRUE(m.faceMaterial.empty());
  EXPECT_TRUE(m.materials.empty());
  const UVec3 t0 = m.triangles[0], t1 = m.triangles[1];
  EXPECT_EQ(t0.y, t1.x);  // position 2 with normal 1 is shared
  EXPECT_NE(t0.z, t1.z);  // position 3 is split
  EXPECT_EQ(m.positions[t0.z], m.positions[t1.z]);
  // Every corner has the position and normal the file gave it.
  const Vec3 p[4] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}};
  const Vec3 n[3] = {{0, 0, 1}, {0, 0.6f, 0.8f}, {0.6f, 0, 0.8f}};
  const int corners[2][3][2] = {{{0, 0}, {1, 0}, {2, 1}}, {{1, 0}, {3, 2}, {2, 2}}};
  for (int t = 0; t < 2; ++t)
    for (int k = 0; k < 3; ++k) {
      const uint32_t v = m.triangles[t][k];
      EXPECT_EQ(m.positions[v], p[corners[t][k][0]]) << t << "," << k;
      EXPECT_EQ(m.normals[v], n[corners[t][k][1]]) << t << "," << k;
    }
}

TEST_F(ObjTest, PartialNormalsAreDropped) {
  const std::string text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvn 0 0 1\n"
                           "f 1//1 2//1 3//1\nf 2 4 3\n";
  const TriangleMesh m = loadObj(write("pn.obj", text));
  ASSERT_EQ(m.triangles.size(), 2u);
  EXPECT_EQ(m.positions.size(), 4u);
  EXPECT_TRUE(m.normals.empty());
  EXPECT_EQ(m.triangles[0], UVec3(0, 1, 2));
  EXPECT_EQ(m.triangles[1], UVec3(1, 3, 2));
}

TEST_F(ObjTest, PolygonsTriangulatedAndMaterialsPerFace) {
  write("two.mtl", "newmtl a\nKd 1 0 0\nKs 0.5 0.5 0.5\nNs 20\n\nnewmtl b\nKd 0 1 0\nKe 0 0 4\n");
  const std::string text =
      "mtllib two.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 2 0\n"
      "f 1 2 3\n"          // no material yet
      "usemtl b\nf 1 2 3 4\n"  // quad -> 2 triangles
      "usemtl a\nf 1 2 3 5 4\n";  // pentagon -> 3 triangles
  const TriangleMesh m = loadObj(write("poly.obj", text));
  ASSERT_EQ(m.triangles.size(), 6u);
  ASSERT_EQ(m.materials.size(), 2u);
  EXPECT_EQ(m.materials[0].kd, Vec3(1, 0, 0));
  EXPECT_EQ(m.materials[0].ks, Vec3(0.5f));
  EXPECT_EQ(m.materials[0].ns, 20.0f);
  EXPECT_EQ(m.materials[1].ke, Vec3(0, 0, 4));
  const std::vector<int32_t> expected = {-1, 1, 1, 0, 0, 0};
  EXPECT_EQ(m.faceMaterial, expected);
  // Triangulated faces keep their corners (any fan order is fine): the quad covers 1..4.
  std::set<uint32_t> quad;
  for (int t = 1; t <= 2; ++t)
    for (int k = 0; k < 3; ++k) quad.insert(m.triangles[t][k]);
  EXPECT_EQ(quad, (std::set<uint32_t>{0, 1, 2, 3}));
}

TEST_F(ObjTest, LoadMeshDispatch) {
  const std::string path = write("TRI.OBJ", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  EXPECT_EQ(loadMesh(path).triangles.size(), 1u);
  try {
    loadMesh(write("tri.off", "OFF\n"));
    ADD_FAILURE() << "no error for .off";
  } catch (const MeshError& e) {
    EXPECT_NE(std::string(e.what()).find("tri.off"), std::string::npos);
  }
}

/// \file test_ply.cpp
/// PLY loader: the three formats, property/list types, skipping, triangulation, normals, and
/// malformed input (every case must throw MeshError naming the file, never crash).

#include "voxcone/core/error.h"
#include "voxcone/scene/mesh.h"

#include <gtest/gtest.h>

#include "../support/mesh_errors.h"
#include "../support/temp_dir.h"

#include <chrono>
#include <cstdint>
#include <cstring>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <unistd.h>
#include <vector>

namespace fs = std::filesystem;
using namespace voxcone;

namespace {

/// A per-test temporary directory, removed at the end.
class PlyTest : public test::TempDirTest {
};

/// Appends scalars to a binary PLY body in the chosen byte order.
struct BinaryWriter {
  bool bigEndian = false;
  std::string bytes;
  template <typename T> void put(T v) {
    char b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    if (bigEndian)
      for (size_t i = 0; i < sizeof(T) / 2; ++i) std::swap(b[i], b[sizeof(T) - 1 - i]);
    bytes.append(b, sizeof(T));
  }
};

/// Five vertices (a triangle and a quad sharing an edge) used for the format comparison.
const float kPos[5][3] = {{0.5f, -1.25f, 3.0f}, {1.0f, 0.0f, 0.0f},     {0.0f, 2.0f, -0.125f},
                          {1.5f, 1.5f, 1e-3f},  {-7.0f, 0.25f, 100.0f}};

const char* kHeaderCommon =
    "element vertex 5\n"
    "property float x\nproperty float y\nproperty float z\n"
    "element face 2\n"
    "property list uchar int vertex_indices\n"
    "end_header\n";

std::string asciiFile() {
  return std::string("ply\nformat ascii 1.0\ncomment test\n") + kHeaderCommon +
         "0.5 -1.25 3\n1 0 0\n0 2 -0.125\n1.5 1.5 0.001\n-7 0.25 100\n"
         "3 0 1 2\n4 1 3 4 2\n";
}

std::string binaryFile(bool bigEndian) {
  BinaryWriter w{bigEndian, {}};
  for (const auto& p : kPos)
    for (float c : p) w.put<float>(c);
  w.put<uint8_t>(3);
  for (int32_t i : {0, 1, 2}) w.put<int32_t>(i);
  w.put<uint8_t>(4);
  for (int32_t i : {1, 3, 4, 2}) w.put<int32_t>(i);
  return std::string("ply\nformat ") + (bigEndian ? "binary_big_endian" : "binary_little_endian") +
         " 1.0\n" + kHeaderCommon + w.bytes;
}

void expectMeshError(const std::string& path, const std::string& needle = "") {
  test::expectMeshError([](const std::string& p) { return loadPly(p); }, path, needle);
}

/// Header + body for a one-triangle-per-face file with the given list and index types.
std::string typedFaceFile(const std::string& countType, const std::string& indexType, bool ascii) {
  std::string h = std::string("ply\nformat ") + (ascii ? "ascii" : "binary_little_endian") +
                  " 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                  "element face 2\nproperty list " + countType + " " + indexType +
                  " vertex_indices\nend_header\n";
  if (ascii) return h + "0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n";
  BinaryWriter w;
  const float v[4][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  for (const auto& p : v)
    for (float c : p) w.put(c);
  auto putCount = [&](int n) {
    if (countType == "uchar" || countType == "uint8") w.put<uint8_t>(uint8_t(n));
    else if (countType == "ushort" || countType == "uint16") w.put<uint16_t>(uint16_t(n));
    else if (countType == "int" || countType == "int32") w.put<int32_t>(n);
    else w.put<uint32_t>(uint32_t(n));
  };
  auto putIndex = [&](int i) {
    if (indexType == "int" || indexType == "int32") w.put<int32_t>(i);
    else if (indexType == "uint" || indexType == "uint32") w.put<uint32_t>(uint32_t(i));
    else if (indexType == "short" || indexType == "int16") w.put<int16_t>(int16_t(i));
    else if (indexType == "ushort" || indexType == "uint16") w.put<uint16_t>(uint16_t(i));
    else w.put<uint8_t>(uint8_t(i));
  };
  putCount(3);
  for (int i : {0, 1, 2}) putIndex(i);
  putCount(3);
  for (int i : {0, 2, 3}) putIndex(i);
  return h + w.bytes;
}

}  // namespace

TEST_F(PlyTest, AllThreeFormatsGiveIdenticalMeshes) {
  const TriangleMesh a = loadPly(write("a.ply", asciiFile()));
  const TriangleMesh le = loadPly(write("le.ply", binaryFile(false)));
  const TriangleMesh be = loadPly(write("be.ply", binaryFile(true)));
  for (const TriangleMesh* m : {&a, &le, &be}) {
    ASSERT_EQ(m->positions.size(), 5u);
    ASSERT_EQ(m->triangles.size(), 3u);
    EXPECT_TRUE(m->normals.empty());
    EXPECT_TRUE(m->materials.empty());
    for (int i = 0; i < 5; ++i)
      for (int c = 0; c < 3; ++c) EXPECT_EQ(m->positions[i][c], kPos[i][c]) << i << "," << c;
    EXPECT_EQ(m->triangles[0], UVec3(0, 1, 2));
    // The quad (1,3,4,2) is fan-triangulated around its first corner.
    EXPECT_EQ(m->triangles[1], UVec3(1, 3, 4));
    EXPECT_EQ(m->triangles[2], UVec3(1, 4, 2));
  }
}

TEST_F(PlyTest, ListCountAndIndexTypes) {
  const char* countTypes[] = {"uchar", "uint8", "ushort", "uint16", "int", "int32", "uint", "uint32"};
  const char* indexTypes[] = {"int", "int32", "uint", "uint32", "short", "int16",
                              "ushort", "uint16", "uchar", "uint8"};
  int n = 0;
  for (const char* ct : countTypes)
    for (const char* it : indexTypes)
      for (bool ascii : {false, true}) {
        const std::string name = std::string(ct) + "_" + it + (ascii ? "_a" : "_b") + ".ply";
        const TriangleMesh m = loadPly(write(name, typedFaceFile(ct, it, ascii)));
        ASSERT_EQ(m.triangles.size(), 2u) << name;
        EXPECT_EQ(m.triangles[0], UVec3(0, 1, 2)) << name;
        EXPECT_EQ(m.triangles[1], UVec3(0, 2, 3)) << name;
        ++n;
      }
  EXPECT_EQ(n, 160);
}

TEST_F(PlyTest, VertexIndexNameAndPolygons) {
  const std::string text =
      "ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\nproperty float y\n"
      "property float z\nelement face 4\nproperty list uchar uint vertex_index\nend_header\n"
      "0 0 0\n1 0 0\n1 1 0\n0 1 0\n0.5 2 0\n-1 1 0\n"
      "4 0 1 2 3\n"   // quad -> 2 triangles
      "2 0 1\n"       // line: skipped
      "0\n"           // empty: skipped
      "6 0 1 2 4 3 5\n";  // hexagon -> 4 triangles
  const TriangleMesh m = loadPly(write("poly.ply", text));
  ASSERT_EQ(m.triangles.size(), 6u);
  EXPECT_EQ(m.triangles[0], UVec3(0, 1, 2));
  EXPECT_EQ(m.triangles[1], UVec3(0, 2, 3));
  EXPECT_EQ(m.triangles[2], UVec3(0, 1, 2));
  EXPECT_EQ(m.triangles[3], UVec3(0, 2, 4));
  EXPECT_EQ(m.triangles[4], UVec3(0, 4, 3));
  EXPECT_EQ(m.triangles[5], UVec3(0, 3, 5));
}

TEST_F(PlyTest, ExtraPropertiesAndElementsSkippedInAllFormats) {
  // Vertex: extra scalars of every type around x,y,z, and a list; face: a scalar before and a
  // list after the indices; extra elements with lists before and after (range_grid, edge).
  const std::string header =
      "comment extra stuff\nobj_info scanner 1\n"
      "element range_grid 3\nproperty list uchar int vertex_indices\n"
      "element vertex 3\nproperty char a\nproperty double x\nproperty uint8 b\nproperty short c\n"
      "property float y\nproperty ushort d\nproperty int e\nproperty uint f\n"
      "property list ushort float g\nproperty float64 z\nproperty float32 confidence\n"
      "element face 1\nproperty int16 flags\nproperty list uchar int vertex_indices\n"
      "property list int double texcoord\n"
      "element edge 2\nproperty int vertex1\nproperty int32 vertex2\nproperty uchar red\n"
      "element material 1\nproperty list uint8 uint8 name\n"
      "end_header\n";
  const std::string ascii = "ply\nformat ascii 1.0\n" + header +
                            "1 7\n0\n2 8 9\n"
                            "-5 1.5 200 -300 2.5 60000 -7 4000000000 2 0.1 0.2 3.5 0.9\n"
                            "1 4.5 2 600 5.5 1 -1 1 0 6.5 0.5\n"
                            "-1 7.5 3 3 8.5 65535 0 0 3 1 2 3 9.5 1\n"
                            "77 3 0 2 1 4 0.1 0.2 0.3 0.4\n"
                            "0 1 255\n1 2 0\n"
                            "3 97 98 99\n";
  auto body = [](bool big) {
    BinaryWriter w{big, {}};
    // range_grid: 3 rows with lists of 1, 0, 2 ints
    w.put<uint8_t>(1), w.put<int32_t>(7);
    w.put<uint8_t>(0);
    w.put<uint8_t>(2), w.put<int32_t>(8), w.put<int32_t>(9);
    const double x[3] = {1.5, 4.5, 7.5};
    const float y[3] = {2.5f, 5.5f, 8.5f};
    const double z[3] = {3.5, 6.5, 9.5};
    for (int i = 0; i < 3; ++i) {
      w.put<int8_t>(-5);
      w.put<double>(x[i]);
      w.put<uint8_t>(200);
      w.put<int16_t>(-300);
      w.put<float>(y[i]);
      w.put<uint16_t>(60000);
      w.put<int32_t>(-7);
      w.put<uint32_t>(4000000000u);
      w.put<uint16_t>(uint16_t(i));  // list of i floats
      for (int k = 0; k < i; ++k) w.put<float>(0.1f);
      w.put<double>(z[i]);
      w.put<float>(0.9f);
    }
    w.put<int16_t>(77);
    w.put<uint8_t>(3), w.put<int32_t>(0), w.put<int32_t>(2), w.put<int32_t>(1);
    w.put<int32_t>(4);
    for (double t : {0.1, 0.2, 0.3, 0.4}) w.put<double>(t);
    w.put<int32_t>(0), w.put<int32_t>(1), w.put<uint8_t>(255);
    w.put<int32_t>(1), w.put<int32_t>(2), w.put<uint8_t>(0);
    w.put<uint8_t>(3), w.put<uint8_t>(97), w.put<uint8_t>(98), w.put<uint8_t>(99);
    return w.bytes;
  };
  const std::string le = "ply\nformat binary_little_endian 1.0\n" + header + body(false);
  const std::string be = "ply\nformat binary_big_endian 1.0\n" + header + body(true);
  for (const auto& [name, text] : {std::pair<std::string, std::string>{"x_a.ply", ascii},
                                   {"x_le.ply", le},
                                   {"x_be.ply", be}}) {
    const TriangleMesh m = loadPly(write(name, text));
    ASSERT_EQ(m.positions.size(), 3u) << name;
    EXPECT_EQ(m.positions[0], Vec3(1.5f, 2.5f, 3.5f)) << name;
    EXPECT_EQ(m.positions[1], Vec3(4.5f, 5.5f, 6.5f)) << name;
    EXPECT_EQ(m.positions[2], Vec3(7.5f, 8.5f, 9.5f)) << name;
    ASSERT_EQ(m.triangles.size(), 1u) << name;
    EXPECT_EQ(m.triangles[0], UVec3(0, 2, 1)) << name;
    EXPECT_TRUE(m.normals.empty()) << name;
  }
}

TEST_F(PlyTest, ScalarCoordinateTypesConverted) {
  // x as int, y as uchar, z as short; big endian.
  BinaryWriter w{true, {}};
  w.put<int32_t>(-3), w.put<uint8_t>(250), w.put<int16_t>(-32000);
  w.put<int32_t>(7), w.put<uint8_t>(0), w.put<int16_t>(12);
  const std::string text =
      "ply\nformat binary_big_endian 1.0\nelement vertex 2\nproperty int x\nproperty uchar y\n"
      "property short z\nend_header\n" + w.bytes;
  const TriangleMesh m = loadPly(write("types.ply", text));
  ASSERT_EQ(m.positions.size(), 2u);
  EXPECT_EQ(m.positions[0], Vec3(-3.0f, 250.0f, -32000.0f));
  EXPECT_EQ(m.positions[1], Vec3(7.0f, 0.0f, 12.0f));
  EXPECT_TRUE(m.triangles.empty());  // a point set has no faces
}

TEST_F(PlyTest, NormalsReadOnlyWhenComplete) {
  const std::string text =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nproperty float nx\nproperty float ny\nproperty float nz\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
      "0 0 0 0 0 1\n1 0 0 0 0.6 0.8\n0 1 0 -1 0 0\n3 0 1 2\n";
  const TriangleMesh m = loadPly(write("n.ply", text));
  ASSERT_EQ(m.normals.size(), 3u);
  EXPECT_EQ(m.normals[0], Vec3(0, 0, 1));
  EXPECT_EQ(m.normals[1], Vec3(0, 0.6f, 0.8f));
  EXPECT_EQ(m.normals[2], Vec3(-1, 0, 0));

  // Binary little endian with double normals.
  BinaryWriter w;
  w.put<float>(1), w.put<float>(2), w.put<float>(3), w.put<double>(0), w.put<double>(1),
      w.put<double>(0);
  const std::string bin =
      "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n"
      "property float y\nproperty float z\nproperty double nx\nproperty double ny\n"
      "property double nz\nend_header\n" + w.bytes;
  const TriangleMesh b = loadPly(write("nb.ply", bin));
  ASSERT_EQ(b.normals.size(), 1u);
  EXPECT_EQ(b.normals[0], Vec3(0, 1, 0));

  // Only nx and ny: no normals.
  const std::string partial =
      "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
      "property float z\nproperty float nx\nproperty float ny\nend_header\n1 2 3 0.5 0.5\n";
  const TriangleMesh p = loadPly(write("np.ply", partial));
  EXPECT_EQ(p.positions.size(), 1u);
  EXPECT_TRUE(p.normals.empty());
}

TEST_F(PlyTest, CrlfHeaderAndLooseAsciiWhitespace) {
  const std::string text =
      "ply\r\nformat ascii 1.0\r\nelement vertex 3\r\nproperty float x\r\nproperty float y\r\n"
      "property float z\r\nelement face 1\r\nproperty list uchar int vertex_indices\r\n"
      "end_header\r\n  +1e0\t2.5e-1 -0\r\n3 4 5 \r\n6 7 8\r\n3 2 1 0";  // no final newline
  const TriangleMesh m = loadPly(write("crlf.ply", text));
  ASSERT_EQ(m.positions.size(), 3u);
  EXPECT_EQ(m.positions[0], Vec3(1.0f, 0.25f, 0.0f));
  ASSERT_EQ(m.triangles.size(), 1u);
  EXPECT_EQ(m.triangles[0], UVec3(2, 1, 0));
}

TEST_F(PlyTest, ShippedTetrahedron) {
  const TriangleMesh m = loadPly(std::string(VOXCONE_SOURCE_DIR) + "/data/meshes/tetra.ply");
  ASSERT_EQ(m.positions.size(), 4u);
  ASSERT_EQ(m.triangles.size(), 4u);
  // Every triangle faces away from the centroid.
  const Vec3 c(0.25f);
  for (const UVec3& t : m.triangles) {
    const Vec3 n = glm::cross(m.positions[t.y] - m.positions[t.x], m.positions[t.z] - m.positions[t.x]);
    EXPECT_GT(glm::dot(n, m.positions[t.x] - c), 0.0f);
  }
}

TEST_F(PlyTest, LoadMeshDispatchesByExtension) {
  const std::string upper = write("UPPER.PLY", asciiFile());
  EXPECT_EQ(loadMesh(upper).triangles.size(), 3u);
  const std::string other = write("mesh.stl", asciiFile());
  EXPECT_THROW(loadMesh(other), MeshError);
  EXPECT_THROW(loadMesh(write("noext", asciiFile())), MeshError);
}

TEST_F(PlyTest, MalformedHeadersThrow) {
  const std::string v3 = "element vertex 1\nproperty float x\nproperty float y\nproperty float z\n";
  expectMeshError((m_dir / "missing.ply").string(), "cannot open");
  expectMeshError(write("empty.ply", ""), "not a PLY");
  expectMeshError(write("notply.ply", "solid cube\nfacet normal 0 0 1\n"), "not a PLY");
  expectMeshError(write("plyx.ply", "plyx\nformat ascii 1.0\nend_header\n"), "not a PLY");
  expectMeshError(write("badformat.ply", "ply\nformat binary_middle_endian 1.0\n" + v3 +
                                             "end_header\n1 2 3\n"),
                  "line 2: unknown format");
  expectMeshError(write("noformat.ply", "ply\n" + v3 + "end_header\n1 2 3\n"), "format");
  expectMeshError(write("noend.ply", "ply\nformat ascii 1.0\n" + v3), "missing end_header");
  expectMeshError(write("noend2.ply", "ply\nformat ascii 1.0\n" + v3 + "1 2 3\n"), "line 7");
  expectMeshError(write("badtype.ply", "ply\nformat ascii 1.0\nelement vertex 1\n"
                                       "property float128 x\nend_header\n"),
                  "line 4: unknown type");
  expectMeshError(write("propfirst.ply", "ply\nformat ascii 1.0\nproperty float x\nend_header\n"),
                  "line 3");
  expectMeshError(write("noy.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
                                   "property float z\nend_header\n1 2\n"),
                  "'y'");
  expectMeshError(write("novertex.ply", "ply\nformat ascii 1.0\nend_header\n"), "vertex");
  expectMeshError(write("negcount.ply", "ply\nformat ascii 1.0\nelement vertex -3\n"
                                        "property float x\nproperty float y\nproperty float z\n"
                                        "end_header\n"),
                  "negative");
  expectMeshError(write("badcount.ply", "ply\nformat ascii 1.0\nelement vertex 3x\n"
                                        "property float x\nproperty float y\nproperty float z\n"
                                        "end_header\n"),
                  "line 3");
  expectMeshError(write("floatcount.ply", "ply\nformat ascii 1.0\n" + v3 +
                                              "element face 1\nproperty list float int "
                                              "vertex_indices\nend_header\n1 2 3\n3 0 0 0\n"),
                  "count type");
  expectMeshError(write("noindices.ply", "ply\nformat ascii 1.0\n" + v3 +
                                             "element face 1\nproperty int foo\nend_header\n"
                                             "1 2 3\n4\n"),
                  "vertex_indices");
  expectMeshError(write("junk.ply", "ply\nformat ascii 1.0\nfoo bar\n" + v3 + "end_header\n"),
                  "line 3");
}

TEST_F(PlyTest, MalformedBodiesThrow) {
  const std::string head = "element vertex 3\nproperty float x\nproperty float y\n"
                           "property float z\nelement face 2\n"
                           "property list uchar int vertex_indices\nend_header\n";
  const std::string asciiHead = "ply\nformat ascii 1.0\n" + head;
  const std::string binHead = "ply\nformat binary_little_endian 1.0\n" + head;

  // Header only.
  expectMeshError(write("hdr_a.ply", asciiHead), "truncated: expected 3 vertices, got 0");
  expectMeshError(write("hdr_b.ply", binHead), "truncated: expected 3 vertices, got 0");
  // Truncated in the faces.
  expectMeshError(write("tr_a.ply", asciiHead + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1"),
                  "truncated: expected 2 faces, got 1");
  BinaryWriter w;
  for (int i = 0; i < 9; ++i) w.put<float>(float(i));
  const std::string vertsBin = w.bytes;
  w.put<uint8_t>(3), w.put<int32_t>(0), w.put<int32_t>(1), w.put<int32_t>(2);
  w.put<uint8_t>(3), w.put<int32_t>(0);
  expectMeshError(write("tr_b.ply", binHead + w.bytes), "truncated: expected 2 faces, got 1");
  expectMeshError(write("tr_bv.ply", binHead + vertsBin.substr(0, 20)),
                  "truncated: expected 3 vertices, got 1");
  // Bad values.
  expectMeshError(write("bad_a.ply", asciiHead + "0 0 0\n1 zero 0\n"), "line 11: bad vertex value");
  expectMeshError(write("bad_a2.ply", asciiHead + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2.5\n"),
                  "line 13: bad face value");
  expectMeshError(write("inf_a.ply", asciiHead + "0 0 0\n1e60 0 0\n0 1 0\n"), "line 11");
  expectMeshError(write("nan_a.ply", asciiHead + "0 0 0\nnan 0 0\n0 1 0\n"),
                  "line 11: vertex 1: non-finite");
  // Index out of range names the face.
  expectMeshError(write("oor_a.ply", asciiHead + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 3\n"),
                  "face 1: vertex index 3 out of range");
  expectMeshError(write("neg_a.ply", asciiHead + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 -1 2\n"),
                  "face 1");
  BinaryWriter o;
  o.bytes = vertsBin;
  o.put<uint8_t>(3), o.put<int32_t>(0), o.put<int32_t>(1), o.put<int32_t>(2);
  o.put<uint8_t>(3), o.put<int32_t>(0), o.put<int32_t>(1000000), o.put<int32_t>(2);
  expectMeshError(write("oor_b.ply", binHead + o.bytes), "face 1: vertex index 1000000");
  // Negative list count.
  expectMeshError(write("negl_a.ply", asciiHead + "0 0 0\n1 0 0\n0 1 0\n-3 0 1 2\n3 0 1 2\n"),
                  "negative");
  const std::string intHead = "ply\nformat binary_little_endian 1.0\nelement vertex 3\n"
                              "property float x\nproperty float y\nproperty float z\n"
                              "element face 2\nproperty list int int vertex_indices\nend_header\n";
  BinaryWriter n;
  n.bytes = vertsBin;
  n.put<int32_t>(-1);
  n.put<int32_t>(0);
  expectMeshError(write("negl_b.ply", intHead + n.bytes), "negative");
  // A list count far beyond the file.
  BinaryWriter h;
  h.bytes = vertsBin;
  h.put<int32_t>(2000000000);
  h.put<int32_t>(0);
  expectMeshError(write("hugelist_b.ply", intHead + h.bytes), "truncated");
}

TEST_F(PlyTest, AbsurdCountsDoNotAllocate) {
  const std::string v3 = "property float x\nproperty float y\nproperty float z\n";
  // 4e9 vertices in a tiny file: too many for 32-bit indices.
  expectMeshError(write("v4e9_b.ply", "ply\nformat binary_little_endian 1.0\nelement vertex "
                                      "4000000000\n" + v3 + "end_header\n" + std::string(64, 'x')),
                  "vertices");
  expectMeshError(write("v4e9_a.ply", "ply\nformat ascii 1.0\nelement vertex 4000000000\n" + v3 +
                                          "end_header\n0 0 0\n"),
                  "vertices");
  // Large but representable counts are checked against the file size before allocating.
  expectMeshError(write("v4e8_b.ply", "ply\nformat binary_big_endian 1.0\nelement vertex "
                                      "400000000\n" + v3 + "end_header\n" + std::string(64, 'x')),
                  "truncated: expected 400000000 vertices, got 5");
  expectMeshError(write("v4e8_a.ply", "ply\nformat ascii 1.0\nelement vertex 400000000\n" + v3 +
                                          "end_header\n0 0 0\n1 1 1\n"),
                  "truncated: expected 400000000 vertices, got 2");
  expectMeshError(write("f_b.ply", "ply\nformat binary_little_endian 1.0\nelement vertex 0\n" + v3 +
                                       "element face 3000000000\nproperty list uchar int "
                                       "vertex_indices\nend_header\n" + std::string(10, '\0')),
                  "truncated: expected 3000000000 faces");
  expectMeshError(write("f_a.ply", "ply\nformat ascii 1.0\nelement vertex 0\n" + v3 +
                                       "element face 3000000000\nproperty list uchar int "
                                       "vertex_indices\nend_header\n0\n0\n"),
                  "truncated: expected 3000000000 faces, got 2");
  expectMeshError(write("e_b.ply", "ply\nformat binary_little_endian 1.0\nelement vertex 0\n" + v3 +
                                       "element range_grid 9000000000000000000\nproperty list "
                                       "uchar int vertex_indices\nend_header\n" +
                                       std::string(10, '\0')),
                  "truncated");
  expectMeshError(write("e_big.ply", "ply\nformat ascii 1.0\nelement vertex 99999999999999999999\n" +
                                         v3 + "end_header\n"),
                  "line 3");
  // Elements without properties hold no data, whatever their count.
  const TriangleMesh m = loadPly(write("empty_el.ply", "ply\nformat binary_little_endian 1.0\n"
                                                       "element nothing 4000000000\nelement vertex 0\n" +
                                                       v3 + "end_header\n"));
  EXPECT_TRUE(m.positions.empty());
}

TEST_F(PlyTest, TruncationAndCorruptionNeverCrash) {
  // Every prefix of a valid file, in each format, either loads or throws MeshError.
  int loaded = 0, thrown = 0;
  for (const auto& [name, full] : {std::pair<std::string, std::string>{"p_a.ply", asciiFile()},
                                   {"p_le.ply", binaryFile(false)},
                                   {"p_be.ply", binaryFile(true)}}) {
    for (size_t len = 0; len < full.size(); ++len) {
      const std::string path = write(name, full.substr(0, len));
      try {
        loadPly(path);
        ++loaded;
      } catch (const MeshError&) {
        ++thrown;
      }
    }
  }
  EXPECT_GT(thrown, 100);
  // Random byte corruption (fixed seed) of the binary and the ascii file.
  std::mt19937 rng(1234);
  for (int trial = 0; trial < 600; ++trial) {
    std::string s = trial % 3 == 0 ? asciiFile() : binaryFile(trial % 3 == 2);
    const int edits = 1 + int(rng() % 4);
    for (int e = 0; e < edits; ++e) s[rng() % s.size()] = char(rng() & 0xff);
    const std::string path = write("fuzz.ply", s);
    try {
      loadPly(path);
      ++loaded;
    } catch (const MeshError&) {
      ++thrown;
    }
  }
  EXPECT_GT(loaded, 0);
}

TEST(PlyModels, StanfordDragon) {
  const std::string path = std::string(VOXCONE_SOURCE_DIR) + "/data/models/dragon_vrip.ply";
  if (!fs::exists(path)) GTEST_SKIP() << "run tools/fetch_models.sh to fetch " << path;
  const auto t0 = std::chrono::steady_clock::now();
  const TriangleMesh m = loadPly(path);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("dragon: %zu vertices, %zu triangles, loaded in %.3f s\n", m.positions.size(),
              m.triangles.size(), seconds);
  EXPECT_EQ(m.positions.size(), 437645u);
  EXPECT_EQ(m.triangles.size(), 871414u);
  EXPECT_TRUE(m.normals.empty());
  const Bounds3 b = m.bounds();
  EXPECT_NEAR(b.lo.x, -0.108324, 1e-6);
  EXPECT_NEAR(b.hi.x, 0.0965662, 1e-6);
  EXPECT_NEAR(b.lo.y, 0.0527295, 1e-6);
  EXPECT_NEAR(b.hi.y, 0.197173, 1e-6);
  EXPECT_NEAR(b.lo.z, -0.0504143, 1e-6);
  EXPECT_NEAR(b.hi.z, 0.0412075, 1e-6);
}

TEST(PlyModels, StanfordBunny) {
  const std::string path = std::string(VOXCONE_SOURCE_DIR) + "/data/models/bunny.ply";
  if (!fs::exists(path)) GTEST_SKIP() << "run tools/fetch_models.sh to fetch " << path;
  const TriangleMesh m = loadPly(path);
  EXPECT_EQ(m.positions.size(), 1839u);
  EXPECT_EQ(m.triangles.size(), 3674u);
}

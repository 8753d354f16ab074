// glTF 2.0: cornell-box written as a .gltf and a .glb by the small writer below (its triangles,
// Lambertian and emissive materials, camera) renders as the JSON scene does; node transforms
// (TRS and matrices, a mirroring scale) place the triangles where the matrices say; a textured
// quad (TEXCOORD_0 with glTF's top-left origin) shows its texels where the JSON quad does;
// KHR_lights_punctual lights convert as Blender's importer converts them; the material mapping;
// a JSON {"type": "gltf"} shape; and errors for what cannot be rendered.

#include "voxcone/core/error.h"
#include "voxcone/image/image_io.h"
#include "voxcone/image/metrics.h"
#include "voxcone/scene/gltf.h"
#include "voxcone/scene/scene.h"

#include "../support/render_helpers.h"
#include "../support/report.h"
#include "../support/temp_dir.h"

#include <nlohmann/json.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

namespace voxcone {
namespace {

using nlohmann::json;
using test::renderWith;
using test::report;

std::string base64(const std::string& bytes) {
  static const char* k = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const uint32_t v = (uint8_t(bytes[i]) << 16) | (uint8_t(bytes[i + 1]) << 8) | uint8_t(bytes[i + 2]);
    for (int s : {18, 12, 6, 0}) out += k[(v >> s) & 63];
  }
  if (i < bytes.size()) {
    uint32_t v = uint8_t(bytes[i]) << 16;
    if (i + 1 < bytes.size()) v |= uint8_t(bytes[i + 1]) << 8;
    out += k[(v >> 18) & 63];
    out += k[(v >> 12) & 63];
    out += i + 1 < bytes.size() ? k[(v >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

/// A small glTF writer: one buffer, accessors appended as they come.
struct GltfBuilder {
  json doc = {{"asset", {{"version", "2.0"}}}, {"scenes", {{{"nodes", json::array()}}}}, {"scene", 0},
              {"nodes", json::array()}, {"meshes", json::array()}, {"materials", json::array()},
              {"accessors", json::array()}, {"bufferViews", json::array()}, {"buffers", json::array()}};
  std::string bin;

  int accessor(const void* data, size_t bytes, size_t count, int componentType, const char* type) {
    while (bin.size() % 4) bin += '\0';
    doc["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", bin.size()}, {"byteLength", bytes}});
    bin.append(static_cast<const char*>(data), bytes);
    doc["accessors"].push_back({{"bufferView", doc["bufferViews"].size() - 1}, {"componentType", componentType},
                                {"count", count}, {"type", type}});
    return int(doc["accessors"].size() - 1);
  }
  int positions(const std::vector<Vec3>& p) {
    const int a = accessor(p.data(), p.size() * 12, p.size(), 5126, "VEC3");
    Vec3 lo(1e30f), hi(-1e30f);
    for (const Vec3& v : p) {
      lo = glm::min(lo, v);
      hi = glm::max(hi, v);
    }
    doc["accessors"][size_t(a)]["min"] = {lo.x, lo.y, lo.z};
    doc["accessors"][size_t(a)]["max"] = {hi.x, hi.y, hi.z};
    return a;
  }
  int indices(const std::vector<uint32_t>& i) { return accessor(i.data(), i.size() * 4, i.size(), 5125, "SCALAR"); }
  int uvs(const std::vector<Vec2>& t) { return accessor(t.data(), t.size() * 8, t.size(), 5126, "VEC2"); }
  int mesh(int pos, int idx, int material, int uv = -1) {
    json prim = {{"attributes", {{"POSITION", pos}}}, {"indices", idx}, {"material", material}};
    if (uv >= 0) prim["attributes"]["TEXCOORD_0"] = uv;
    doc["meshes"].push_back({{"primitives", {prim}}});
    return int(doc["meshes"].size() - 1);
  }
  int node(json n) {
    doc["nodes"].push_back(std::move(n));
    return int(doc["nodes"].size() - 1);
  }
  void root(int n) { doc["scenes"][0]["nodes"].push_back(n); }

  /// As .gltf (the buffer a data URI) or .glb.
  void write(const std::string& path) const {
    json d = doc;
    const bool glb = path.size() > 4 && path.substr(path.size() - 4) == ".glb";
    if (!glb) {
      d["buffers"] = {{{"byteLength", bin.size()}, {"uri", "data:application/octet-stream;base64," + base64(bin)}}};
      std::ofstream(path, std::ios::binary) << d.dump();
      return;
    }
    d["buffers"] = {{{"byteLength", bin.size()}}};
    std::string text = d.dump();
    while (text.size() % 4) text += ' ';
    std::string body = bin;
    while (body.size() % 4) body += '\0';
    const auto u32 = [](std::string& s, uint32_t v) { s.append(reinterpret_cast<const char*>(&v), 4); };
    std::string out;
    u32(out, 0x46546C67u);  // "glTF"
    u32(out, 2u);
    u32(out, uint32_t(12 + 8 + text.size() + 8 + body.size()));
    u32(out, uint32_t(text.size()));
    u32(out, 0x4E4F534Au);  // JSON
    out += text;
    u32(out, uint32_t(body.size()));
    u32(out, 0x004E4942u);  // BIN
    out += body;
    std::ofstream(path, std::ios::binary) << out;
  }
};

/// The camera's node matrix (column-major): columns right, up, back (-forward), eye.
json cameraMatrix(const Camera& c) {
  const Vec3 f = glm::normalize(c.target() - c.position());
  const Vec3 right = glm::normalize(glm::cross(f, c.up()));
  const Vec3 up = glm::cross(right, f);
  const Vec3 cols[4] = {right, up, -f, c.position()};
  json m = json::array();
  for (int col = 0; col < 4; ++col)
    for (int r = 0; r < 4; ++r) m.push_back(r < 3 ? double(cols[col][r]) : (col == 3 ? 1.0 : 0.0));
  return m;
}

/// `scene` (Lambertian and emissive materials only) as glTF: one mesh per material, vertices
/// as they are (no transform), its camera.
GltfBuilder fromScene(const Scene& scene) {
  GltfBuilder b;
  for (size_t m = 0; m < scene.materials.size(); ++m) {
    const Material& mat = scene.materials[m];
    json gm = {{"pbrMetallicRoughness",
                {{"baseColorFactor", {mat.albedo.x, mat.albedo.y, mat.albedo.z, 1.0}}, {"metallicFactor", 0.0},
                 {"roughnessFactor", 1.0}}}};
    if (mat.isEmissive()) {
      const float peak = std::max({mat.emission.x, mat.emission.y, mat.emission.z});
      gm["emissiveFactor"] = {mat.emission.x / peak, mat.emission.y / peak, mat.emission.z / peak};
      gm["extensions"] = {{"KHR_materials_emissive_strength", {{"emissiveStrength", peak}}}};
      b.doc["extensionsUsed"] = {"KHR_materials_emissive_strength"};
    }
    b.doc["materials"].push_back(gm);
    std::vector<Vec3> pos;
    std::vector<uint32_t> idx;
    for (size_t t = 0; t < scene.triangles.size(); ++t) {
      if (scene.triMaterial[t] != m) continue;
      for (int k = 0; k < 3; ++k) {
        idx.push_back(uint32_t(pos.size()));
        pos.push_back(scene.positions[scene.triangles[t][k]]);
      }
    }
    if (idx.empty()) continue;
    b.root(b.node({{"mesh", b.mesh(b.positions(pos), b.indices(idx), int(m))}}));
  }
  b.doc["cameras"] = {{{"type", "perspective"},
                       {"perspective", {{"yfov", double(glm::radians(scene.camera.fovYDeg())) }, {"znear", 0.01},
                                        {"aspectRatio", double(scene.render.width) / scene.render.height}}}}};
  b.root(b.node({{"camera", 0}, {"matrix", cameraMatrix(scene.camera)}}));
  return b;
}

class Gltf : public test::TempDirTest {};

TEST_F(Gltf, CornellBoxRendersAsTheJsonScene) {
  const Scene box = test::cornellBox();
  const GltfBuilder b = fromScene(box);
  b.write(path("box.gltf"));
  b.write(path("box.glb"));
  RenderSettings s = box.render;
  s.width = s.height = 32;
  s.spp = 64;
  const Image ref = renderWith(box, "path", s).image;
  for (const char* file : {"box.gltf", "box.glb"}) {
    std::vector<std::string> warnings;
    const Scene g = loadGltfScene(path(file), &warnings);
    EXPECT_TRUE(warnings.empty()) << warnings.front();
    EXPECT_EQ(g.triangleCount(), box.triangleCount());
    EXPECT_EQ(g.render.width, g.render.height);  // aspectRatio 1
    EXPECT_NEAR(g.camera.fovYDeg(), box.camera.fovYDeg(), 1e-3);
    // The same triangles (in another order), camera and materials: the same image up to the
    // light samples' order over the triangles (seen: relMSE 2e-4 at 64 spp, cells within 1%).
    const Image img = renderWith(g, "path", s).image;
    const double relMse = compareImages(img, ref).relMse;
    report(std::string(file) + " relMSE", relMse, 5e-3);
    EXPECT_LT(relMse, 5e-3) << file;
    double worst = 0.0;
    for (const RegionError& e : regionErrors(img, ref, 4)) {
      EXPECT_NEAR(e.meanTest.y / e.meanReference.y, 1.0, 0.05) << file;
      worst = std::max(worst, std::fabs(e.meanTest.y / e.meanReference.y - 1.0));
    }
    report(std::string(file) + " worst cell |ratio - 1|", worst, 0.05);
  }
}

TEST_F(Gltf, NodeTransformsPlaceTheTriangles) {
  GltfBuilder b;
  b.doc["materials"].push_back({{"pbrMetallicRoughness", {{"metallicFactor", 0.0}}}, {"emissiveFactor", {1, 1, 1}}});
  const int mesh = b.mesh(b.positions({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)}), b.indices({0, 1, 2}), 0);
  // TRS: scale 2, rotate 90 degrees about +z, translate (5, 0, 0); its child translates (0, 0, 1)
  // in the parent's frame; a third node mirrors x by a matrix.
  const double h = std::sqrt(0.5);
  const int child = b.node({{"mesh", mesh}, {"translation", {0, 0, 1}}});
  b.root(b.node({{"mesh", mesh}, {"scale", {2, 2, 2}}, {"rotation", {0, 0, h, h}}, {"translation", {5, 0, 0}},
                 {"children", {child}}}));
  b.root(b.node({{"mesh", mesh}, {"matrix", {-1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}}}));
  b.doc["cameras"] = {{{"type", "perspective"}, {"perspective", {{"yfov", 0.8}, {"znear", 0.01}}}}};
  b.root(b.node({{"camera", 0}, {"translation", {0, 0, 10}}}));
  b.write(path("t.gltf"));
  std::vector<std::string> warnings;
  const Scene s = loadGltfScene(path("t.gltf"), &warnings);
  ASSERT_EQ(s.triangleCount(), 3u);
  const auto vertex = [&](size_t t, int k) { return s.positions[s.triangles[t][k]]; };
  // (1, 0, 0) scaled 2 -> (2, 0, 0), turned -> (0, 2, 0), moved -> (5, 2, 0).
  report("worst vertex or camera position error",
         std::max({glm::length(vertex(0, 1) - Vec3(5, 2, 0)), glm::length(vertex(1, 0) - Vec3(5, 0, 2)),
                   glm::length(s.camera.position() - Vec3(0, 0, 10))}),
         1e-5);
  EXPECT_NEAR(glm::length(vertex(0, 1) - Vec3(5, 2, 0)), 0.0f, 1e-5f);
  // The child: (0, 0, 1) in the parent's frame is (0, 0, 2) in the world, plus (5, 0, 0).
  EXPECT_NEAR(glm::length(vertex(1, 0) - Vec3(5, 0, 2)), 0.0f, 1e-5f);
  // The mirror keeps the front side where the file had it: the winding flips with x.
  const Vec3 n = glm::cross(vertex(2, 1) - vertex(2, 0), vertex(2, 2) - vertex(2, 0));
  EXPECT_GT(n.z, 0.0f);
  EXPECT_NEAR(glm::length(s.camera.position() - Vec3(0, 0, 10)), 0.0f, 1e-5f);
  EXPECT_GT(glm::dot(s.camera.target() - s.camera.position(), Vec3(0, 0, -1)), 0.0f);
}

TEST_F(Gltf, ATexturedQuadShowsItsTexelsWhereTheJsonQuadDoes) {
  // 2 x 2 texels in an EXR? glTF images are PNG or JPEG: a PNG of sRGB codes.
  Image img(2, 2);
  img.at(0, 0) = Vec3(0.8f, 0.1f, 0.1f);  // top left
  img.at(1, 0) = Vec3(0.1f, 0.6f, 0.1f);
  img.at(0, 1) = Vec3(0.1f, 0.1f, 0.5f);
  img.at(1, 1) = Vec3(0.1f);
  writeImage(path("tex.png"), img, json::object());
  GltfBuilder b;
  b.doc["images"] = {{{"uri", "tex.png"}}};
  b.doc["textures"] = {{{"source", 0}}};
  b.doc["materials"].push_back(
      {{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}}}, {"metallicFactor", 0.0}, {"roughnessFactor", 1.0}}}});
  // The quad x, y in [-1, 1] at z = 0; glTF uv (0, 0) is the image's top-left: vertex (-1, 1).
  const int pos = b.positions({Vec3(-1, -1, 0), Vec3(1, -1, 0), Vec3(1, 1, 0), Vec3(-1, 1, 0)});
  const int uv = b.uvs({Vec2(0, 1), Vec2(1, 1), Vec2(1, 0), Vec2(0, 0)});
  b.root(b.node({{"mesh", b.mesh(pos, b.indices({0, 1, 2, 0, 2, 3}), 0, uv)}}));
  b.doc["cameras"] = {{{"type", "perspective"}, {"perspective", {{"yfov", 2.0 * std::atan(0.25)}, {"znear", 0.01}}}}};
  b.root(b.node({{"camera", 0}, {"translation", {0, 0, 4}}}));
  b.write(path("quad.gltf"));
  // The glTF's meshes in a JSON scene under a constant sky, against the JSON quad with the PNG.
  const auto scene = [&](const std::string& shape) {
    return parseScene(R"({
      "camera": {"position": [0, 0, 4], "target": [0, 0, 0], "up": [0, 1, 0], "fov_y_deg": 28.0724869},
      "render": {"width": 16, "height": 16, "spp": 16, "max_depth": 4},
      "materials": {"tex": {"type": "lambertian", "albedo_texture": "tex.png"}},
      "shapes": [)" + shape + R"(],
      "lights": [{"type": "environment", "radiance": [1, 1, 1]}]})",
                      "s", path(""));
  };
  const Scene g = scene(R"({"type": "gltf", "file": "quad.gltf"})");
  const Scene j = scene(R"({"type": "quad", "material": "tex", "vertices": [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]})");
  ASSERT_EQ(g.textures.size(), 2u);  // the JSON material's tex.png and the glTF's image
  const Image a = renderWith(g, "whitted", g.render).image;
  const Image c = renderWith(j, "whitted", j.render).image;
  const double relMse = compareImages(a, c).relMse;
  report("glTF vs JSON relMSE", relMse, 1e-3);
  EXPECT_LT(relMse, 1e-3);
  // Pixel (4, 4) sees the top-left texel's centre (uv 0.28, 0.72 in voxcone's frame): red.
  report("pixel (4, 4) red / green (lower bound)", a.at(4, 4).x / a.at(4, 4).y, 3.0);
  EXPECT_GT(a.at(4, 4).x, 3.0f * a.at(4, 4).y);
}

TEST_F(Gltf, LightsConvertAsBlendersImporter) {
  GltfBuilder b;
  b.doc["materials"].push_back({{"pbrMetallicRoughness", {{"metallicFactor", 0.0}}}});
  b.root(b.node({{"mesh", b.mesh(b.positions({Vec3(-1, 0, -1), Vec3(1, 0, -1), Vec3(0, 0, 1)}), b.indices({0, 2, 1}), 0)}}));
  b.doc["extensionsUsed"] = {"KHR_lights_punctual"};
  b.doc["extensions"] = {{"KHR_lights_punctual",
                          {{"lights",
                            {{{"type", "point"}, {"intensity", 683.0}, {"color", {1.0, 0.5, 0.25}}},
                             {{"type", "directional"}, {"intensity", 1366.0}}}}}}};
  b.root(b.node({{"translation", {0, 2, 0}}, {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}}));
  // The directional light turned to shine straight down (-z turned 90 degrees about x: -y).
  const double h = std::sqrt(0.5);
  b.root(b.node({{"rotation", {-h, 0, 0, h}}, {"extensions", {{"KHR_lights_punctual", {{"light", 1}}}}}}));
  b.doc["cameras"] = {{{"type", "perspective"}, {"perspective", {{"yfov", 0.8}, {"znear", 0.01}}}}};
  b.root(b.node({{"camera", 0}, {"translation", {0, 1, 5}}}));
  b.write(path("l.gltf"));
  std::vector<std::string> warnings;
  const Scene s = loadGltfScene(path("l.gltf"), &warnings);
  ASSERT_EQ(s.pointLights.size(), 1u);
  ASSERT_EQ(s.directionalLights.size(), 1u);
  // 683 cd = 1 W/sr (Blender: 4 pi W of point power), coloured; 1366 lx = 2 W/m^2.
  report("worst light intensity, position, irradiance or direction error",
         std::max({glm::length(s.pointLights[0].intensity - Vec3(1.0f, 0.5f, 0.25f)),
                   glm::length(s.pointLights[0].position - Vec3(0, 2, 0)),
                   glm::length(s.directionalLights[0].irradiance - Vec3(2.0f)),
                   glm::length(s.directionalLights[0].direction - Vec3(0, -1, 0))}),
         1e-5);
  EXPECT_NEAR(glm::length(s.pointLights[0].intensity - Vec3(1.0f, 0.5f, 0.25f)), 0.0f, 1e-5f);
  EXPECT_NEAR(glm::length(s.pointLights[0].position - Vec3(0, 2, 0)), 0.0f, 1e-5f);
  EXPECT_NEAR(glm::length(s.directionalLights[0].irradiance - Vec3(2.0f)), 0.0f, 1e-5f);
  EXPECT_NEAR(glm::length(s.directionalLights[0].direction - Vec3(0, -1, 0)), 0.0f, 1e-5f);
}

TEST_F(Gltf, MaterialsMapAndWarnWhatTheyDrop) {
  GltfBuilder b;
  const auto pbr = [](double metallic, double roughness) {
    return json{{"pbrMetallicRoughness",
                 {{"baseColorFactor", {0.5, 0.4, 0.3, 1.0}}, {"metallicFactor", metallic}, {"roughnessFactor", roughness}}}};
  };
  b.doc["materials"] = {pbr(0, 1), pbr(1, 0.5), pbr(0, 0.3), pbr(0, 0.2)};
  b.doc["materials"][3]["extensions"] = {{"KHR_materials_transmission", {{"transmissionFactor", 1.0}}},
                                         {"KHR_materials_ior", {{"ior", 1.33}}}};
  b.doc["materials"][3]["normalTexture"] = {{"index", 0}};
  b.doc["images"] = json::array();
  for (int m = 0; m < 4; ++m)
    b.root(b.node({{"mesh", b.mesh(b.positions({Vec3(m, 0, 0), Vec3(m + 1, 0, 0), Vec3(m, 1, 0)}), b.indices({0, 1, 2}), m)}}));
  b.doc["cameras"] = {{{"type", "perspective"}, {"perspective", {{"yfov", 0.8}, {"znear", 0.01}}}}};
  b.root(b.node({{"camera", 0}, {"translation", {0, 0, 10}}}));
  b.doc["lights"] = json::array();
  b.doc["extensions"] = {{"KHR_lights_punctual", {{"lights", {{{"type", "point"}, {"intensity", 100.0}}}}}}};
  b.root(b.node({{"translation", {0, 0, 3}}, {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}}));
  b.write(path("m.gltf"));
  std::vector<std::string> warnings;
  const Scene s = loadGltfScene(path("m.gltf"), &warnings);
  const auto matOf = [&](size_t t) { return s.materials[s.triMaterial[t]]; };
  EXPECT_EQ(matOf(0).type, MaterialType::Lambertian);
  EXPECT_NEAR(matOf(0).albedo.x, 0.5f, 1e-6f);
  EXPECT_EQ(matOf(1).type, MaterialType::RoughConductor);
  EXPECT_NEAR(matOf(1).roughness, 0.25f, 1e-6f);  // alpha = roughness^2
  EXPECT_NEAR(matOf(1).specular.y, 0.4f, 1e-6f);
  // A non-metal of roughness < 1: its specular layer a rough coat of glTF's default index.
  EXPECT_EQ(matOf(2).type, MaterialType::RoughPlastic);
  EXPECT_NEAR(matOf(2).roughness, 0.09f, 1e-6f);
  EXPECT_NEAR(matOf(2).ior, 1.5f, 1e-6f);
  EXPECT_NEAR(matOf(2).albedo.z, 0.3f, 1e-6f);
  EXPECT_GE(matOf(2).coat.internalReflectance, 0.0f);  // prepared by the loader's finalize
  EXPECT_EQ(matOf(3).type, MaterialType::RoughDielectric);
  EXPECT_NEAR(matOf(3).ior, 1.33f, 1e-6f);
  report("worst mapped parameter error",
         std::max({std::fabs(matOf(0).albedo.x - 0.5f), std::fabs(matOf(1).roughness - 0.25f),
                   std::fabs(matOf(1).specular.y - 0.4f), std::fabs(matOf(2).roughness - 0.09f),
                   std::fabs(matOf(2).ior - 1.5f), std::fabs(matOf(2).albedo.z - 0.3f), std::fabs(matOf(3).ior - 1.33f)}),
         1e-6);
  std::string all;
  for (const std::string& w : warnings) all += w + "\n";
  EXPECT_EQ(all.find("specular layer"), std::string::npos) << all;
  EXPECT_NE(all.find("normal map"), std::string::npos) << all;
}

TEST_F(Gltf, Errors) {
  // The one-line error of loading `name` (written as `text` first when given).
  const auto errorOf = [&](const std::string& name, const std::string& text = "") {
    if (!text.empty()) std::ofstream(path(name), std::ios::binary) << text;
    try {
      loadGltfScene(path(name));
    } catch (const Error& e) {
      const std::string m = e.what();
      EXPECT_EQ(m.find('\n'), std::string::npos) << m;
      return m;
    }
    return std::string("no error");
  };
  EXPECT_NE(errorOf("a.gltf", "{ not json").find("a.gltf"), std::string::npos);
  EXPECT_NE(errorOf("b.glb", "glTF garbage").find("b.glb"), std::string::npos);
  // A required extension voxcone does not read.
  const std::string ext = errorOf("c.gltf", R"({"asset": {"version": "2.0"}, "extensionsRequired": ["KHR_draco_mesh_compression"],
                                                "extensionsUsed": ["KHR_draco_mesh_compression"]})");
  EXPECT_NE(ext.find("KHR_draco_mesh_compression"), std::string::npos) << ext;
  // No camera.
  GltfBuilder b;
  b.doc["materials"].push_back({{"emissiveFactor", {1, 1, 1}}});
  b.root(b.node({{"mesh", b.mesh(b.positions({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)}), b.indices({0, 1, 2}), 0)}}));
  b.write(path("d.gltf"));
  const std::string noCamera = errorOf("d.gltf");
  EXPECT_NE(noCamera.find("no perspective camera"), std::string::npos) << noCamera;
  // An index past the positions.
  GltfBuilder c;
  c.doc["materials"].push_back({{"emissiveFactor", {1, 1, 1}}});
  c.root(c.node({{"mesh", c.mesh(c.positions({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)}), c.indices({0, 1, 7}), 0)}}));
  c.doc["cameras"] = {{{"type", "perspective"}, {"perspective", {{"yfov", 0.8}, {"znear", 0.01}}}}};
  c.root(c.node({{"camera", 0}, {"translation", {0, 0, 10}}}));
  c.write(path("e.gltf"));
  const std::string badIndex = errorOf("e.gltf");
  EXPECT_NE(badIndex.find("out of range"), std::string::npos) << badIndex;
}

}  // namespace
}  // namespace voxcone

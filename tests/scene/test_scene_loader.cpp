// The JSON scene format: canonical scenes load with the numbers of SPEC.md; bad input gives a
// SceneError naming the file and the key path.

#include "voxcone/core/error.h"
#include "voxcone/scene/scene.h"

#include "../support/test_scenes.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <vector>

namespace voxcone {
namespace {

const char* kMinimal = R"({
  "camera": {"position": [0, 0, -5], "target": [0, 0, 0]},
  "materials": {"m": {"type": "lambertian", "albedo": 0.5, "emission": [1, 1, 1]}},
  "shapes": [{"type": "quad", "material": "m", "vertices": [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]}]
})";

/// The message of the SceneError that parsing `text` throws ("" if none).
std::string errorOf(const std::string& text) {
  try {
    parseScene(text, "test.json", ".");
  } catch (const SceneError& e) {
    return e.what();
  }
  return "";
}

std::string replaced(std::string s, const std::string& from, const std::string& to) {
  const auto pos = s.find(from);
  EXPECT_NE(pos, std::string::npos) << from;
  return s.replace(pos, from.size(), to);
}

TEST(SceneLoader, MinimalSceneLoads) {
  const Scene s = parseScene(kMinimal, "test.json", ".");
  EXPECT_EQ(s.triangleCount(), 2u);
  EXPECT_EQ(s.lightCount(), 2u);
  EXPECT_EQ(s.render.width, 256);
  EXPECT_FLOAT_EQ(s.materials[0].albedo.y, 0.5f);
}

TEST(SceneLoader, BadInputNamesTheKeyPath) {
  const std::string m = kMinimal;
  struct Case {
    std::string text, expect;
  };
  const std::vector<Case> cases = {
      {"{", "invalid JSON"},
      {"", "invalid JSON"},
      {"[1,2]", "expected an object"},
      {replaced(m, "\"target\"", "\"targt\""), "camera.target: missing required key"},
      {replaced(m, "\"position\": [0, 0, -5]", "\"position\": [0, 0, -5], \"fov\": 3"), "camera.fov: unknown key"},
      {replaced(m, "\"albedo\": 0.5", "\"albedo\": -0.5"), "materials.m.albedo"},
      {replaced(m, "\"albedo\": 0.5", "\"albedo\": [1, 2]"), "materials.m.albedo: expected an array of 3 numbers"},
      // Reflectances above one would create energy (an albedo of 2 rendered a mean of 7.9).
      {replaced(m, "\"albedo\": 0.5", "\"albedo\": 2"), "materials.m.albedo: value 2 out of range [0, 1]"},
      {replaced(m, "\"albedo\": 0.5", "\"albedo\": [0.5, 1.2, 0.3]"),
       "materials.m.albedo: component 1 is 1.2, out of range [0, 1]"},
      {replaced(m, "\"type\": \"lambertian\", \"albedo\": 0.5", "\"type\": \"mirror\", \"specular\": 1.5"),
       "materials.m.specular: value 1.5 out of range [0, 1]"},
      {replaced(m, "\"emission\": [1, 1, 1]", "\"emission\": [1, -1, 1]"), "materials.m.emission: component 1 is -1"},
      {replaced(m, "\"emission\": [1, 1, 1]", "\"emission\": [1e999, 1, 1]"),
       "invalid JSON: a number too large for a double at line 3: 1e999"},
      {replaced(m, "\"type\": \"lambertian\"", "\"type\": \"principled\""), "materials.m.type: unknown material type"},
      {replaced(m, "\"material\": \"m\"", "\"material\": \"x\""), "shapes[0].material: unknown material 'x'"},
      {replaced(m, "\"type\": \"quad\"", "\"type\": \"triangle\""), "shapes[0].vertices: expected 3 vertices"},
      {replaced(m, "\"type\": \"quad\"", "\"type\": \"quad\", \"colour\": 1"), "shapes[0].colour: unknown key"},
      {replaced(m, "\"type\": \"quad\"", "\"type\": \"mesh\", \"file\": \"nope.ply\""), "shapes[0].file"},
      {replaced(m, "\"emission\": [1, 1, 1]", "\"emission\": [0, 0, 0]"), "no light"},
      {replaced(m, "\"camera\"", "\"render\": {\"spp\": 0}, \"camera\""), "render.spp: value 0 out of range"},
      {replaced(m, "\"camera\"", "\"render\": {\"width\": 1.5}, \"camera\""), "render.width: expected an integer"},
      {replaced(m, "\"camera\"", "\"render\": {\"sampler\": \"halton\"}, \"camera\""), "render.sampler: unknown sampler 'halton'"},
      {replaced(m, "\"camera\"", "\"render\": {\"light_sampler\": \"bvh\"}, \"camera\""), "render.light_sampler: must be"},
      {replaced(m, "\"camera\"", "\"render\": {\"light_split\": 91}, \"camera\""), "render.light_split: value 91 out of range"},
      {replaced(m, "\"camera\"", "\"render\": {\"light_split\": -1}, \"camera\""), "render.light_split: value -1 out of range"},
      {replaced(m, "\"target\": [0, 0, 0]", "\"target\": [0, 0, -5]"), "camera.target: target equals position"},
      {replaced(m, "\"materials\"", "\"extra\": {}, \"materials\""), "extra: unknown key"},
  };
  for (const Case& c : cases) {
    const std::string err = errorOf(c.text);
    EXPECT_NE(err.find("test.json"), std::string::npos) << err;
    EXPECT_NE(err.find(c.expect), std::string::npos) << "expected '" << c.expect << "' in: " << err;
  }
}

TEST(SceneLoader, LightSamplerAndSplitAngle) {
  const Scene d = parseScene(kMinimal, "test.json", ".");
  EXPECT_TRUE(d.render.lightTree);
  EXPECT_EQ(d.render.lightSplitDeg, 45.0f);
  EXPECT_TRUE(d.splitting());
  const Scene s = parseScene(replaced(kMinimal, "\"camera\"", "\"render\": {\"light_split\": 0}, \"camera\""), "test.json", ".");
  EXPECT_FALSE(s.splitting());
  const Scene p = parseScene(
      replaced(kMinimal, "\"camera\"", "\"render\": {\"light_sampler\": \"power\", \"light_split\": 20}, \"camera\""),
      "test.json", ".");
  EXPECT_FALSE(p.render.lightTree);
  EXPECT_EQ(p.render.lightSplitDeg, 20.0f);
  EXPECT_FALSE(p.splitting());  // splitting is the tree's
}

TEST(SceneLoader, MissingFileIsAnError) {
  EXPECT_THROW(loadScene("/nonexistent/scene.json"), SceneError);
}

TEST(SceneLoader, CornellBoxHasTheSpecNumbers) {
  const Scene s = loadScene(test::sourceDir() + "/data/scenes/cornell-box.json");
  EXPECT_EQ(s.triangleCount(), 32u);  // 5 walls + light + 10 block quads, 2 triangles each
  EXPECT_FLOAT_EQ(s.bounds().hi.x, 556.0f);
  EXPECT_FLOAT_EQ(s.bounds().hi.y, 548.8f);
  EXPECT_FLOAT_EQ(s.bounds().hi.z, 559.2f);
  EXPECT_FLOAT_EQ(s.camera.fovYDeg(), 39.3077f);
  // The light: one-sided, facing down, radiance (17, 12, 4), area 130 x 105.
  float lightArea = 0.0f;
  for (uint32_t t = 0; t < s.triangleCount(); ++t) {
    const Material& m = s.materials[s.triMaterial[t]];
    if (!m.isEmissive()) continue;
    lightArea += s.triangleArea(t);
    EXPECT_EQ(m.emission, Vec3(17, 12, 4));
    const SurfaceHit h = s.surfaceAt(t, 0.3f, 0.3f);
    EXPECT_NEAR(h.geomNormal.y, -1.0f, 1e-6f);
    EXPECT_EQ(s.emitted(h, Vec3(0, -1, 0)), Vec3(17, 12, 4));
    EXPECT_EQ(s.emitted(h, Vec3(0, 1, 0)), Vec3(0.0f));
  }
  EXPECT_NEAR(lightArea, 130.0f * 105.0f, 1e-2f);
  // The red wall's quad split (SPEC: (v0,v1,v2) and (v0,v2,v3)) keeps its vertices.
  bool found = false;
  for (const ShapeInfo& sh : s.shapes)
    if (sh.name == "left_wall") {
      const UVec3 t0 = s.triangles[sh.firstTriangle], t1 = s.triangles[sh.firstTriangle + 1];
      EXPECT_EQ(s.positions[t0.x], Vec3(552.8f, 0, 0));
      EXPECT_EQ(s.positions[t0.z], Vec3(556, 548.8f, 559.2f));
      EXPECT_EQ(s.positions[t1.z], Vec3(556, 548.8f, 0));
      EXPECT_EQ(s.materials[s.triMaterial[sh.firstTriangle]].albedo, Vec3(0.63f, 0.065f, 0.05f));
      found = true;
    }
  EXPECT_TRUE(found);
}

TEST(SceneLoader, EveryCanonicalSceneParses) {
  // The dragon scenes need the fetched mesh; without it they must fail on exactly that file.
  const bool haveDragon = std::filesystem::exists(test::sourceDir() + "/data/models/dragon_vrip.ply");
  for (const char* name : {"cornell-dragon", "cornell-dragon-glass", "cornell-dragon-gold", "cornell-dragon-gold-rough",
                           "cornell-mirror-glass"}) {
    const std::string path = test::sourceDir() + "/data/scenes/" + name + ".json";
    if (haveDragon) {
      const Scene s = loadScene(path);
      EXPECT_EQ(s.triangleCount(), 871414u + 12u) << name;
      // SPEC: the dragon spans 300 mm in x, centred at x = 278, z = 279.6, standing on y = 0.
      Bounds3 b;
      for (const ShapeInfo& sh : s.shapes)
        if (sh.name == "dragon")
          for (uint32_t t = sh.firstTriangle; t < sh.firstTriangle + sh.triangleCount; ++t)
            for (int k = 0; k < 3; ++k) b.extend(s.positions[s.triangles[t][k]]);
      EXPECT_NEAR(b.hi.x - b.lo.x, 300.0f, 0.01f) << name;
      EXPECT_NEAR(b.center().x, 278.0f, 0.01f) << name;
      EXPECT_NEAR(b.center().z, 279.6f, 0.01f) << name;
      EXPECT_NEAR(b.lo.y, 0.0f, 0.01f) << name;
    } else {
      try {
        loadScene(path);
        ADD_FAILURE() << name << " loaded without the dragon";
      } catch (const SceneError& e) {
        EXPECT_NE(std::string(e.what()).find("dragon_vrip.ply"), std::string::npos) << e.what();
      }
    }
  }
}

TEST(SceneLoader, MeshTransformAndSphere) {
  const std::string dir = ::testing::TempDir();
  {
    std::ofstream f(dir + "/tri.ply");
    f << "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
         "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  }
  const std::string json = std::string(R"({
    "camera": {"position": [0, 0, -5], "target": [0, 0, 0]},
    "materials": {"m": {"type": "lambertian", "emission": 1}},
    "shapes": [{"type": "mesh", "file": "tri.ply", "material": "m",
                "transform": {"scale": 2, "rotate_deg": 90, "rotate_axis": [0, 0, 1], "translate": [10, 0, 0]}},
               {"type": "sphere", "center": [0, 5, 0], "radius": 2, "subdivisions": 1, "material": "m"}]
  })");
  const Scene s = parseScene(json, "t.json", dir);
  ASSERT_EQ(s.triangleCount(), 1u + 80u);
  // (1,0,0) scaled to (2,0,0), rotated 90 degrees about z to (0,2,0), moved to (10,2,0).
  EXPECT_NEAR(s.positions[1].x, 10.0f, 1e-5f);
  EXPECT_NEAR(s.positions[1].y, 2.0f, 1e-5f);
  for (size_t i = 3; i < s.positions.size(); ++i) EXPECT_NEAR(glm::length(s.positions[i] - Vec3(0, 5, 0)), 2.0f, 1e-5f);
}

}  // namespace
}  // namespace voxcone

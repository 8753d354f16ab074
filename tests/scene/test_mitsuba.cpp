// Mitsuba 3 XML scenes: each element's mapping checked against hand-computed values, the errors
// (element, file and line), one-sided BSDFs, the JSON <-> XML conversion, and the Done-means
// test: data/scenes/cornell-box.xml renders as data/scenes/cornell-box.json, region by region.

#include "../support/render_helpers.h"
#include "../support/temp_dir.h"
#include "../support/test_scenes.h"
#include "voxcone/core/error.h"
#include "voxcone/image/metrics.h"
#include "voxcone/scene/bsdf.h"
#include "voxcone/scene/mitsuba.h"

#include <gtest/gtest.h>

#include <cmath>
#include <map>

namespace voxcone {
namespace {

// A 32 x 32 camera at the origin looking along +z, and a point light: enough for a scene to load.
const std::string kSensor = R"(
  <sensor type="perspective">
    <float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0, 0, -10" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="32"/><rfilter type="box"/></film>
  </sensor>
  <emitter type="point"><point name="position" x="0" y="0" z="-5"/><rgb name="intensity" value="1"/></emitter>)";

/// `body` inside <scene> with kSensor (or `sensor`) before it.
std::string xmlScene(const std::string& body, const std::string& sensor = kSensor) {
  return "<?xml version=\"1.0\"?>\n<scene version=\"3.0.0\">" + sensor + "\n" + body + "\n</scene>\n";
}

Scene parse(const std::string& xml, const SceneParameters& params = {}, const std::string& dir = ".") {
  return parseMitsubaScene(xml, "test.xml", dir, params);
}

/// The SceneError message of parsing `xml` ("" when it loads).
std::string errorOf(const std::string& xml, const SceneParameters& params = {}) {
  try {
    parse(xml, params);
  } catch (const SceneError& e) {
    return e.what();
  }
  return "";
}

const std::string kRect = R"(<shape type="rectangle"/>)";

/// Unit geometric normal of triangle t.
Vec3 triNormal(const Scene& s, size_t t) {
  const UVec3& tr = s.triangles[t];
  return glm::normalize(glm::cross(s.positions[tr.y] - s.positions[tr.x], s.positions[tr.z] - s.positions[tr.x]));
}

void expectVec(const Vec3& a, const Vec3& b, float tol = 1e-5f) {
  EXPECT_NEAR(a.x, b.x, tol);
  EXPECT_NEAR(a.y, b.y, tol);
  EXPECT_NEAR(a.z, b.z, tol);
}

// ---------------------------------------------------------------------------------------------
// Transforms

/// The scene's vertex positions for a rectangle with `transform` as its to_world.
std::vector<Vec3> rectangleWith(const std::string& transform) {
  const Scene s = parse(xmlScene("<shape type=\"rectangle\"><transform name=\"to_world\">" + transform + "</transform></shape>"));
  return s.positions;
}

TEST(MitsubaTransform, TranslateScaleRotateMatrixAndTheirOrder) {
  // Rectangle corners: (-1,-1,0) (1,-1,0) (1,1,0) (-1,1,0).
  // Scale then translate (first listed is applied first): x' = 2x + 10.
  auto p = rectangleWith(R"(<scale x="2"/><translate x="10"/>)");
  expectVec(p[0], Vec3(8, -1, 0));
  expectVec(p[2], Vec3(12, 1, 0));
  // Translate then scale: x' = 2(x + 10).
  p = rectangleWith(R"(<translate x="10"/><scale x="2"/>)");
  expectVec(p[0], Vec3(18, -1, 0));
  // Uniform scale as one value, vector translate as value=.
  p = rectangleWith(R"(<scale value="3"/><translate value="1, 2, 3"/>)");
  expectVec(p[1], Vec3(4, -1, 3));
  // Rotate 90 degrees about z (right-handed): (1,-1,0) -> (1,1,0); (-1,-1,0) -> (1,-1,0).
  p = rectangleWith(R"(<rotate z="1" angle="90"/>)");
  expectVec(p[1], Vec3(1, 1, 0));
  expectVec(p[0], Vec3(1, -1, 0));
  // The same rotation with the axis as value=.
  EXPECT_EQ(rectangleWith(R"(<rotate value="0, 0, 1" angle="90"/>)"), p);
  // About x by 90: (x, y, z) -> (x, -z, y): (1, 1, 0) -> (1, 0, 1).
  p = rectangleWith(R"(<rotate x="1" angle="90"/>)");
  expectVec(p[2], Vec3(1, 0, 1));
  // A row-major matrix: translation in the last column.
  p = rectangleWith(R"(<matrix value="1 0 0 5  0 1 0 6  0 0 1 7  0 0 0 1"/>)");
  expectVec(p[0], Vec3(4, 5, 7));
  // A row-major matrix that is not symmetric: x' = y, y' = 2x (rows "0 1 0 0", "2 0 0 0").
  p = rectangleWith(R"(<matrix value="0 1 0 0  2 0 0 0  0 0 1 0  0 0 0 1"/>)");
  expectVec(p[1], Vec3(-1, 2, 0));
  // Composition: rotate z 90, then scale x by 2, then translate: (1,-1,0) -> (1,1,0) -> (2,1,0) -> (2,1,5).
  p = rectangleWith(R"(<rotate z="1" angle="90"/><scale x="2"/><translate z="5"/>)");
  expectVec(p[1], Vec3(2, 1, 5));
  // A lookat on a shape: local z along the view, x = cross(up, dir): origin (0,0,0), target
  // (1,0,0), up y: dir = +x, left = cross(y, x) = -z, new up = +y; (1,-1,0) -> -z - y.
  p = rectangleWith(R"(<lookat origin="0,0,0" target="1,0,0" up="0,1,0"/>)");
  expectVec(p[1], Vec3(0, -1, -1));
}

TEST(MitsubaTransform, BadTransformsNameTheElementAndLine) {
  const std::string e = errorOf(xmlScene("<shape type=\"rectangle\">\n<transform name=\"to_world\">\n<shear value=\"1\"/>\n</transform></shape>"));
  EXPECT_NE(e.find("<shear>"), std::string::npos) << e;
  EXPECT_NE(e.find("test.xml: line 11"), std::string::npos) << e;
  EXPECT_NE(errorOf(xmlScene(R"(<shape type="rectangle"><transform name="to_world"><matrix value="1 2 3"/></transform></shape>)")).find("16 values"), std::string::npos);
  EXPECT_NE(errorOf(xmlScene(R"(<shape type="rectangle"><transform name="to_world"><scale x="0"/></transform></shape>)")).find("scale by zero"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// Sensor

std::string sensorXml(int w, int h, const std::string& fovParams, const std::string& transform = "") {
  return R"(<sensor type="perspective">)" + fovParams +
         (transform.empty() ? "" : "<transform name=\"to_world\">" + transform + "</transform>") +
         R"(<film type="hdrfilm"><integer name="width" value=")" + std::to_string(w) + R"("/><integer name="height" value=")" +
         std::to_string(h) + R"("/><rfilter type="box"/></film></sensor>
         <emitter type="point"><point name="position" value="0,0,1"/></emitter>)";
}

float fovY(int w, int h, const std::string& axis, float fov = 60.0f) {
  const std::string params = "<float name=\"fov\" value=\"" + std::to_string(fov) + "\"/>" +
                             (axis.empty() ? "" : "<string name=\"fov_axis\" value=\"" + axis + "\"/>");
  return parse(xmlScene(kRect, sensorXml(w, h, params))).camera.fovYDeg();
}

TEST(MitsubaSensor, FovAxesFollowMitsubasParseFov) {
  // 200 x 100 (aspect 2), fov 60. x: fovY = 2 atan(tan 30 / 2) = 32.20423.
  EXPECT_NEAR(fovY(200, 100, "x"), 32.204228f, 1e-4f);
  EXPECT_NEAR(fovY(200, 100, ""), 32.204228f, 1e-4f);  // Mitsuba's default axis is x
  EXPECT_NEAR(fovY(200, 100, "y"), 60.0f, 1e-5f);
  // diagonal: d = 2 tan 30, width = d / sqrt(1 + 1/4), fovY = 2 atan(width / (2 * 2)) = 28.95502.
  EXPECT_NEAR(fovY(200, 100, "diagonal"), 28.955024f, 1e-4f);
  // smaller / larger: the y axis is the smaller one at aspect 2.
  EXPECT_NEAR(fovY(200, 100, "smaller"), 60.0f, 1e-5f);
  EXPECT_NEAR(fovY(200, 100, "larger"), 32.204228f, 1e-4f);
  // 100 x 200 (aspect 1/2): x is the smaller axis; fovY = 2 atan(tan 30 * 2) = 98.21321.
  EXPECT_NEAR(fovY(100, 200, "x"), 98.213211f, 1e-4f);
  EXPECT_NEAR(fovY(100, 200, "smaller"), 98.213211f, 1e-4f);
  EXPECT_NEAR(fovY(100, 200, "larger"), 60.0f, 1e-5f);
  EXPECT_NEAR(fovY(100, 200, "diagonal"), 54.623460f, 1e-4f);
  // focal_length 50mm: the diagonal of 36 x 24 mm film, 46.79300 degrees; square: fovY =
  // 2 atan(tan(23.3965) / sqrt 2).
  const Scene s = parse(xmlScene(kRect, sensorXml(64, 64, R"(<string name="focal_length" value="50mm"/>)")));
  const double diagHalf = std::tan(glm::radians(46.793003 / 2.0));
  EXPECT_NEAR(s.camera.fovYDeg(), glm::degrees(2.0 * std::atan(diagHalf / std::sqrt(2.0))), 1e-4);
  EXPECT_NE(errorOf(xmlScene(kRect, sensorXml(64, 64, R"(<float name="fov" value="40"/><string name="fov_axis" value="z"/>)"))).find("fov_axis"),
            std::string::npos);
}

TEST(MitsubaSensor, LookatGivesTheSameUnmirroredImageAsVoxconesCamera) {
  const Scene s = parse(xmlScene(kRect, sensorXml(64, 32, R"(<float name="fov" value="40"/>)",
                                                  R"(<lookat origin="1, 2, 3" target="1, 2, 10" up="0, 1, 0"/>)")));
  expectVec(s.camera.position(), Vec3(1, 2, 3));
  expectVec(s.camera.target(), Vec3(1, 2, 10));
  expectVec(s.camera.up(), Vec3(0, 1, 0));
  EXPECT_EQ(s.render.width, 64);
  EXPECT_EQ(s.render.height, 32);
  // Mitsuba maps camera-local +x = cross(up, dir) = +x here to the image's left: the ray
  // through the right edge goes towards -x, the top edge towards +y.
  const Ray right = s.camera.generateRay(63.5f, 16.0f, 64, 32);
  const Ray top = s.camera.generateRay(32.0f, 0.5f, 64, 32);
  EXPECT_LT(right.dir.x, -0.1f);
  EXPECT_GT(top.dir.y, 0.1f);
  // x half-angle: tan = tan(20) (fov is on x by default) at the film's edge.
  const Ray edge = s.camera.generateRay(64.0f, 16.0f, 64, 32);
  EXPECT_NEAR(-edge.dir.x / edge.dir.z, std::tan(glm::radians(20.0f)), 1e-5f);
}

TEST(MitsubaSensor, TransformsOtherThanLookatAndTheirLimits) {
  // rotate 90 about y: local +z -> +x: the camera looks along +x from (5, 0, 0).
  const Scene s = parse(xmlScene(kRect, sensorXml(32, 32, R"(<float name="fov" value="40"/>)",
                                                  R"(<rotate y="1" angle="90"/><translate x="5"/>)")));
  expectVec(s.camera.position(), Vec3(5, 0, 0));
  expectVec(glm::normalize(s.camera.target() - s.camera.position()), Vec3(1, 0, 0));
  expectVec(s.camera.up(), Vec3(0, 1, 0));
  EXPECT_NE(errorOf(xmlScene(kRect, sensorXml(32, 32, R"(<float name="fov" value="40"/>)", R"(<scale x="-1"/>)"))).find("mirrors"),
            std::string::npos);
  EXPECT_NE(errorOf(xmlScene(kRect, sensorXml(32, 32, R"(<float name="fov" value="40"/>)", R"(<scale x="2"/>)"))).find("unevenly"),
            std::string::npos);
  // near_clip and far_clip are accepted (voxcone's rays start at the pinhole, unbounded).
  EXPECT_EQ(errorOf(xmlScene(kRect, sensorXml(32, 32, R"(<float name="fov" value="40"/><float name="near_clip" value="0.1"/><float name="far_clip" value="100"/>)"))),
            "");
}

TEST(MitsubaSensor, SamplerFilmAndFilters) {
  const std::string sensor = R"(<sensor type="perspective"><float name="fov" value="40"/>
      <sampler type="independent"><integer name="sample_count" value="7"/><integer name="seed" value="3"/></sampler>
      <film type="hdrfilm"><integer name="width" value="20"/><integer name="height" value="10"/>
        <string name="pixel_format" value="rgb"/><rfilter type="box"/></film></sensor>
      <emitter type="point"><point name="position" value="0,0,1"/></emitter>)";
  const Scene s = parse(xmlScene(kRect, sensor));
  EXPECT_EQ(s.render.spp, 7);
  EXPECT_EQ(s.render.seed, 3u);
  EXPECT_EQ(s.render.sampler, SamplerKind::Independent);
  EXPECT_EQ(s.render.width, 20);
  EXPECT_EQ(s.render.height, 10);
  // Without a film: Mitsuba's hdrfilm default 768 x 576; ldsampler is voxcone's Sobol.
  const Scene d = parse(xmlScene(kRect, R"(<sensor type="perspective"><float name="fov" value="40"/><sampler type="ldsampler"/></sensor>
      <emitter type="point"><point name="position" value="0,0,1"/></emitter>)"));
  EXPECT_EQ(d.render.width, 768);
  EXPECT_EQ(d.render.height, 576);
  EXPECT_EQ(d.render.sampler, SamplerKind::Sobol);
  // Any pixel filter but box is an error naming it and its line.
  const std::string g = errorOf(xmlScene(kRect, R"(<sensor type="perspective"><float name="fov" value="40"/>
      <film type="hdrfilm">
        <rfilter type="gaussian"/></film></sensor><emitter type="point"><point name="position" value="0,0,1"/></emitter>)"));
  EXPECT_NE(g.find("unsupported rfilter 'gaussian'"), std::string::npos) << g;
  EXPECT_NE(g.find("line 4"), std::string::npos) << g;
  EXPECT_NE(errorOf(xmlScene(kRect, R"(<sensor type="thinlens"><float name="fov" value="40"/></sensor>)")).find("'thinlens'"),
            std::string::npos);
  EXPECT_NE(errorOf(xmlScene(kRect, "")).find("no <sensor>"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// Integrator: Mitsuba's max_depth

TEST(MitsubaIntegrator, MaxDepthKeepsMitsubasMeaning) {
  const auto depthOf = [](const std::string& v) {
    return parse(xmlScene(kRect + "<integrator type=\"path\"><integer name=\"max_depth\" value=\"" + v + "\"/></integrator>")).render;
  };
  EXPECT_EQ(depthOf("1").maxDepth, 1);
  EXPECT_EQ(depthOf("5").maxDepth, 5);
  EXPECT_EQ(depthOf("5").method, "path");
  EXPECT_EQ(depthOf("-1").maxDepth, 1024);  // unbounded: voxcone's largest
  EXPECT_NE(errorOf(xmlScene(kRect + R"(<integrator type="path"><integer name="max_depth" value="0"/></integrator>)")).find("max_depth 0"),
            std::string::npos);
  EXPECT_NE(errorOf(xmlScene(kRect + R"(<integrator type="bdpt"/>)")).find("unsupported integrator plugin 'bdpt'"), std::string::npos);
  EXPECT_NE(errorOf(xmlScene(kRect + R"(<integrator type="path"><integer name="rr_depth" value="5"/></integrator>)")).find("rr_depth"),
            std::string::npos);
}

TEST(MitsubaIntegrator, MaxDepthOneAndTwoRenderWhatMitsubasDo) {
  // Mitsuba: max_depth 1 shows emitters only, 2 adds direct light. A lit diffuse quad facing
  // the camera with a point light: black at 1, lit at 2, the same at 3 (nothing to bounce off).
  const std::string body = R"(<shape type="rectangle"><transform name="to_world"><scale value="3"/><rotate y="1" angle="180"/></transform>
      <bsdf type="diffuse"><rgb name="reflectance" value="0.5"/></bsdf></shape>)";
  Scene s = parse(xmlScene(body));
  RenderSettings r = s.render;
  r.width = r.height = 8;
  r.spp = 4;
  r.maxDepth = 1;
  EXPECT_EQ(test::imageMean(test::renderWith(s, "path", r).image), Vec3(0.0f));
  r.maxDepth = 2;
  const Vec3 two = test::imageMean(test::renderWith(s, "path", r).image);
  r.maxDepth = 3;
  const Vec3 three = test::imageMean(test::renderWith(s, "path", r).image);
  EXPECT_GT(two.x, 0.0f);
  EXPECT_FLOAT_EQ(two.x, three.x);
}

// ---------------------------------------------------------------------------------------------
// Defaults, $substitution, -D, ids, include

TEST(MitsubaParameters, DefaultsSubstitutionAndOverrides) {
  const std::string sensor = R"(<default name="w" value="48"/><default name="fov" value="30"/>
    <sensor type="perspective"><float name="fov" value="$fov"/><string name="fov_axis" value="y"/>
      <film type="hdrfilm"><integer name="width" value="$w"/><integer name="height" value="$w"/></film></sensor>
    <emitter type="point"><point name="position" value="0,0,1"/></emitter>)";
  Scene s = parse(xmlScene(kRect, sensor));
  EXPECT_EQ(s.render.width, 48);
  EXPECT_FLOAT_EQ(s.camera.fovYDeg(), 30.0f);
  s = parse(xmlScene(kRect, sensor), {{"w", "20"}});
  EXPECT_EQ(s.render.width, 20);
  EXPECT_EQ(s.render.height, 20);
  EXPECT_FLOAT_EQ(s.camera.fovYDeg(), 30.0f);
  // A parameter without a default, given with -D, inside a longer value.
  s = parse(xmlScene(R"(<shape type="rectangle"><transform name="to_world"><translate value="$x, 0, 0"/></transform></shape>)"), {{"x", "7"}});
  expectVec(s.positions[0], Vec3(6, -1, 0));
  const std::string e = errorOf(xmlScene("\n<shape type=\"rectangle\"><transform name=\"to_world\"><translate x=\"$nope\"/></transform></shape>"));
  EXPECT_NE(e.find("undefined parameter $nope"), std::string::npos) << e;
  EXPECT_NE(e.find("line 10"), std::string::npos) << e;
}

TEST(MitsubaParameters, RefAndId) {
  const std::string body = R"(
    <bsdf type="diffuse" id="grey"><rgb name="reflectance" value="0.25"/></bsdf>
    <shape type="rectangle" id="a"><ref id="grey"/></shape>
    <shape type="cube" id="b"><ref name="bsdf" id="grey"/></shape>
    <shape type="rectangle" id="c"/>)";
  const Scene s = parse(xmlScene(body));
  ASSERT_EQ(s.shapes.size(), 3u);
  EXPECT_EQ(s.shapes[0].name, "a");
  // One material for both references; Mitsuba's default BSDF (diffuse 0.5, one-sided) for c.
  EXPECT_EQ(s.triMaterial[s.shapes[0].firstTriangle], s.triMaterial[s.shapes[1].firstTriangle]);
  const Material& grey = s.materials[s.triMaterial[0]];
  EXPECT_EQ(grey.name, "grey");
  EXPECT_EQ(grey.albedo, Vec3(0.25f));
  const Material& def = s.materials[s.triMaterial[s.shapes[2].firstTriangle]];
  EXPECT_EQ(def.albedo, Vec3(0.5f));
  EXPECT_FALSE(def.twoSided);
  EXPECT_NE(errorOf(xmlScene(R"(<shape type="rectangle"><ref id="missing"/></shape>)")).find("no element with id 'missing'"), std::string::npos);
  EXPECT_NE(errorOf(xmlScene(R"(<bsdf type="diffuse" id="x"/><bsdf type="diffuse" id="x"/>)" + kRect)).find("duplicate id 'x'"),
            std::string::npos);
}

class MitsubaInclude : public test::TempDirTest {};

TEST_F(MitsubaInclude, IncludedFilesResolveTheirOwnPaths) {
  std::filesystem::create_directories(m_dir / "parts" / "meshes");
  write("parts/meshes/tri.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  write("parts/shapes.xml", R"(<scene version="3.0.0">
      <bsdf type="diffuse" id="m"><rgb name="reflectance" value="0.3"/></bsdf>
      <shape type="obj"><string name="filename" value="meshes/tri.obj"/><ref id="m"/></shape>
    </scene>)");
  const std::string main = write("main.xml", xmlScene(R"(<include filename="parts/shapes.xml"/>)"));
  const Scene s = loadScene(main);
  ASSERT_EQ(s.triangleCount(), 1u);
  EXPECT_EQ(s.materials[s.triMaterial[0]].albedo, Vec3(0.3f));
  expectVec(s.positions[1], Vec3(1, 0, 0));
  // A cycle is an error, not a hang.
  write("loop.xml", R"(<scene version="3.0.0"><include filename="loop.xml"/></scene>)");
  const std::string loop = write("main2.xml", xmlScene(kRect + R"(<include filename="loop.xml"/>)"));
  try {
    loadScene(loop);
    ADD_FAILURE() << "the cycle loaded";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("include cycle"), std::string::npos) << e.what();
  }
}

// ---------------------------------------------------------------------------------------------
// Shapes

TEST(MitsubaShapes, RectangleCubeDiskSphere) {
  // rectangle: 4 vertices, 2 triangles, [-1,1]^2, normal +z; flipped: -z.
  Scene s = parse(xmlScene(kRect));
  EXPECT_EQ(s.positions.size(), 4u);
  EXPECT_EQ(s.triangleCount(), 2u);
  expectVec(s.bounds().lo, Vec3(-1, -1, 0));
  expectVec(s.bounds().hi, Vec3(1, 1, 0));
  expectVec(triNormal(s, 0), Vec3(0, 0, 1));
  expectVec(triNormal(s, 1), Vec3(0, 0, 1));
  s = parse(xmlScene(R"(<shape type="rectangle"><boolean name="flip_normals" value="true"/></shape>)"));
  expectVec(triNormal(s, 0), Vec3(0, 0, -1));
  // A mirroring to_world keeps the analytic normal (the transformed +z, here still +z).
  s = parse(xmlScene(R"(<shape type="rectangle"><transform name="to_world"><scale x="-1"/></transform></shape>)"));
  expectVec(triNormal(s, 0), Vec3(0, 0, 1));

  // cube: 24 vertices, 12 triangles, [-1,1]^3, every face outward, flat.
  s = parse(xmlScene(R"(<shape type="cube"><boolean name="face_normals" value="true"/></shape>)"));
  EXPECT_FALSE(s.shapes[0].smoothNormals);
  EXPECT_EQ(s.positions.size(), 24u);
  EXPECT_EQ(s.triangleCount(), 12u);
  expectVec(s.bounds().lo, Vec3(-1));
  expectVec(s.bounds().hi, Vec3(1));
  for (size_t t = 0; t < 12; ++t) {
    const UVec3& tr = s.triangles[t];
    const Vec3 centroid = (s.positions[tr.x] + s.positions[tr.y] + s.positions[tr.z]) / 3.0f;
    EXPECT_GT(glm::dot(triNormal(s, t), centroid), 0.3f) << t;
    EXPECT_NEAR(maxComponent(glm::abs(triNormal(s, t))), 1.0f, 1e-6f);
  }
  double area = 0.0;
  for (size_t t = 0; t < 12; ++t) area += s.triangleArea(uint32_t(t));
  EXPECT_NEAR(area, 24.0, 1e-4);

  // disk: a fan of 256 triangles, area pi * (256 / (2 pi)) sin(2 pi / 256) = 3.141277.
  s = parse(xmlScene(R"(<shape type="disk"><transform name="to_world"><scale value="2"/></transform></shape>)"));
  EXPECT_EQ(s.triangleCount(), size_t(kMitsubaDiskSegments));
  EXPECT_EQ(s.positions.size(), size_t(kMitsubaDiskSegments) + 1);
  area = 0.0;
  for (size_t t = 0; t < s.triangleCount(); ++t) area += s.triangleArea(uint32_t(t));
  EXPECT_NEAR(area, 4.0 * 0.5 * 256 * std::sin(2.0 * kPi / 256.0), 1e-3);
  EXPECT_NEAR(area / (4.0 * kPi), 1.0, 2e-4);
  for (size_t t = 0; t < s.triangleCount(); ++t) expectVec(triNormal(s, t), Vec3(0, 0, 1));

  // sphere: geodesic level 5 (20480 triangles), every vertex on the sphere, outward, with radial
  // vertex normals; flip_normals turns both inward.
  s = parse(xmlScene(R"(<shape type="sphere"><point name="center" x="1" y="2" z="3"/><float name="radius" value="2"/></shape>)"));
  EXPECT_EQ(s.triangleCount(), 20480u);
  ASSERT_TRUE(s.shapes[0].smoothNormals);
  for (size_t v = 0; v < s.positions.size(); v += 97) {
    EXPECT_NEAR(glm::length(s.positions[v] - Vec3(1, 2, 3)), 2.0f, 1e-5f);
    expectVec(s.normals[v], glm::normalize(s.positions[v] - Vec3(1, 2, 3)), 1e-5f);
  }
  for (size_t t = 0; t < s.triangleCount(); t += 101) {
    const Vec3 c = s.positions[s.triangles[t].x] - Vec3(1, 2, 3);
    EXPECT_GT(glm::dot(triNormal(s, t), c), 0.0f);
  }
  expectVec(s.bounds().lo, Vec3(-1, 0, 1), 0.01f);  // the poles and rims lie near, not on, vertices
  s = parse(xmlScene(R"(<shape type="sphere"><boolean name="flip_normals" value="true"/></shape>)"));
  EXPECT_LT(glm::dot(triNormal(s, 0), s.positions[s.triangles[0].x]), 0.0f);
  EXPECT_LT(glm::dot(s.normals[0], s.positions[0]), 0.0f);
  EXPECT_NE(errorOf(xmlScene(R"(<shape type="sphere"><transform name="to_world"><scale x="2"/></transform></shape>)")).find("uniform scale"),
            std::string::npos);
}

class MitsubaMeshes : public test::TempDirTest {};

TEST_F(MitsubaMeshes, ObjAndPlyWithFaceNormalsFlipAndToWorld) {
  // Two triangles folded along x = 0 at 90 degrees: (0,0,0) (0,1,0) shared; one in the z = 0
  // plane (normal +z), one in the x = 0 plane (normal +x).
  write("fold.obj", "v 0 0 0\nv 0 1 0\nv 1 0 0\nv 0 0 -1\nf 1 3 2\nf 1 4 2\n");
  const std::string shape = "<shape type=\"obj\"><string name=\"filename\" value=\"fold.obj\"/>";
  Scene s = parse(xmlScene(shape + "</shape>"), {}, m_dir.string());
  ASSERT_EQ(s.triangleCount(), 2u);
  expectVec(triNormal(s, 0), Vec3(0, 0, 1));
  expectVec(triNormal(s, 1), Vec3(1, 0, 0));
  // Without normals in the file and face_normals false, Mitsuba computes vertex normals, angle
  // weighted: the shared vertices (0,0,0) (angle 90 and 90) and (0,1,0) (45 and 45) average
  // the two faces; the others keep their face's normal.
  ASSERT_TRUE(s.shapes[0].smoothNormals);
  expectVec(s.normals[0], glm::normalize(Vec3(1, 0, 1)));
  expectVec(s.normals[1], glm::normalize(Vec3(1, 0, 1)));
  expectVec(s.normals[2], Vec3(0, 0, 1));
  expectVec(s.normals[3], Vec3(1, 0, 0));
  s = parse(xmlScene(shape + "<boolean name=\"face_normals\" value=\"true\"/></shape>"), {}, m_dir.string());
  EXPECT_FALSE(s.shapes[0].smoothNormals);
  // flip_normals reverses the winding; to_world moves the vertices.
  s = parse(xmlScene(shape + "<boolean name=\"face_normals\" value=\"true\"/><boolean name=\"flip_normals\" value=\"true\"/>"
                             "<transform name=\"to_world\"><translate y=\"5\"/></transform></shape>"),
            {}, m_dir.string());
  expectVec(triNormal(s, 0), Vec3(0, 0, -1));
  expectVec(s.positions[1], Vec3(0, 6, 0));
  // PLY with vertex normals: kept (smooth), rotated with to_world.
  write("quad.ply", "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                    "property float nx\nproperty float ny\nproperty float nz\nelement face 1\nproperty list uchar int vertex_indices\n"
                    "end_header\n0 0 0 0 0 1\n1 0 0 0 0 1\n1 1 0 0 0 1\n0 1 0 0 0 1\n4 0 1 2 3\n");
  s = parse(xmlScene(R"(<shape type="ply"><string name="filename" value="quad.ply"/>
      <transform name="to_world"><rotate x="1" angle="-90"/></transform></shape>)"), {}, m_dir.string());
  ASSERT_EQ(s.triangleCount(), 2u);
  ASSERT_TRUE(s.shapes[0].smoothNormals);
  expectVec(s.normals[0], Vec3(0, 1, 0));  // +z rotated -90 about x: +y
  expectVec(triNormal(s, 0), Vec3(0, 1, 0));
  const std::string e = errorOf(xmlScene(R"(<shape type="obj"><string name="filename" value="/nonexistent/x.obj"/></shape>)"));
  EXPECT_NE(e.find("x.obj"), std::string::npos) << e;
}

// ---------------------------------------------------------------------------------------------
// BSDFs

Material bsdf(const std::string& xml) {
  const Scene s = parse(xmlScene("<shape type=\"rectangle\">" + xml + "</shape>"));
  return s.materials[s.triMaterial[0]];
}

TEST(MitsubaBsdf, DiffuseTwosidedAndItsColours) {
  Material m = bsdf(R"(<bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.4, 0.6"/></bsdf>)");
  EXPECT_EQ(m.type, MaterialType::Lambertian);
  EXPECT_EQ(m.albedo, Vec3(0.2f, 0.4f, 0.6f));
  EXPECT_FALSE(m.twoSided);
  EXPECT_EQ(bsdf(R"(<bsdf type="diffuse"><spectrum name="reflectance" value="0.3"/></bsdf>)").albedo, Vec3(0.3f));
  EXPECT_EQ(bsdf(R"(<bsdf type="diffuse"><float name="reflectance" value="0.7"/></bsdf>)").albedo, Vec3(0.7f));
  EXPECT_EQ(bsdf(R"(<bsdf type="diffuse"/>)").albedo, Vec3(0.5f));
  m = bsdf(R"(<bsdf type="twosided"><bsdf type="diffuse"><rgb name="reflectance" value="0.1"/></bsdf></bsdf>)");
  EXPECT_TRUE(m.twoSided);
  EXPECT_EQ(m.albedo, Vec3(0.1f));
  EXPECT_NE(errorOf(xmlScene(R"(<shape type="rectangle"><bsdf type="diffuse"><spectrum name="reflectance" value="400:0.1, 700:0.5"/></bsdf></shape>)"))
                .find("wavelength"),
            std::string::npos);
  EXPECT_NE(errorOf(xmlScene(R"(<shape type="rectangle"><bsdf type="diffuse"><rgb name="reflectance" value="1.5"/></bsdf></shape>)")).find("outside"),
            std::string::npos);
  EXPECT_NE(errorOf(xmlScene(R"(<shape type="rectangle"><bsdf type="diffuse"><texture type="checkerboard" name="reflectance"/></bsdf></shape>)"))
                .find("unsupported texture plugin 'checkerboard'"),
            std::string::npos);
  EXPECT_NE(errorOf(xmlScene(R"(<shape type="rectangle"><bsdf type="twosided"><bsdf type="dielectric"/></bsdf></shape>)")).find("transmissive"),
            std::string::npos);
}

TEST(MitsubaBsdf, DielectricsWithNamedAndNumericIors) {
  Material m = bsdf(R"(<bsdf type="dielectric"/>)");  // Mitsuba's defaults: bk7 inside, air outside
  EXPECT_EQ(m.type, MaterialType::Dielectric);
  EXPECT_FLOAT_EQ(m.ior, 1.5046f / 1.000277f);
  m = bsdf(R"(<bsdf type="dielectric"><string name="int_ior" value="diamond"/><string name="ext_ior" value="water"/></bsdf>)");
  EXPECT_FLOAT_EQ(m.ior, 2.419f / 1.333f);
  m = bsdf(R"(<bsdf type="dielectric"><float name="int_ior" value="1.7"/><float name="ext_ior" value="1"/></bsdf>)");
  EXPECT_FLOAT_EQ(m.ior, 1.7f);
  m = bsdf(R"(<bsdf type="roughdielectric"><float name="alpha" value="0.2"/><string name="int_ior" value="1.5"/></bsdf>)");
  EXPECT_EQ(m.type, MaterialType::RoughDielectric);
  EXPECT_FLOAT_EQ(m.roughness, 0.2f);
  EXPECT_EQ(m.distribution, MicrofacetDistribution::Beckmann);  // Mitsuba's default
  EXPECT_FLOAT_EQ(m.ior, 1.5f / 1.000277f);
  EXPECT_NE(errorOf(xmlScene(R"(<shape type="rectangle"><bsdf type="dielectric"><string name="int_ior" value="unobtainium"/></bsdf></shape>)"))
                .find("unobtainium"),
            std::string::npos);
  const std::string glass = errorOf(xmlScene("<shape type=\"rectangle\">\n<bsdf type=\"thindielectric\"><float name=\"int_ior\" value=\"0.9\"/></bsdf></shape>"));
  EXPECT_NE(glass.find("int_ior = 0.9 is outside"), std::string::npos) << glass;
  EXPECT_NE(glass.find("line 10"), std::string::npos) << glass;
  m = bsdf(R"(<bsdf type="thindielectric"/>)");
  EXPECT_EQ(m.type, MaterialType::ThinDielectric);
  EXPECT_FLOAT_EQ(m.ior, 1.5046f / 1.000277f);
}

TEST(MitsubaBsdf, ConductorsPresetsAndRoughness) {
  Material m = bsdf(R"(<bsdf type="conductor"/>)");  // Mitsuba's default: material none, a perfect mirror
  EXPECT_EQ(m.type, MaterialType::Mirror);
  EXPECT_EQ(m.specular, Vec3(1.0f));
  m = bsdf(R"(<bsdf type="conductor"><string name="material" value="Au"/></bsdf>)");
  EXPECT_EQ(m.type, MaterialType::Conductor);
  expectVec(m.eta, Vec3(0.14312f, 0.37496f, 1.4425f));  // SPEC.md: about (0.143, 0.374, 1.442)
  expectVec(m.k, Vec3(3.9832f, 2.3857f, 1.6032f));
  for (const char* metal : {"Ag", "Al", "Cu", "Cr", "W"})
    EXPECT_EQ(bsdf(std::string("<bsdf type=\"conductor\"><string name=\"material\" value=\"") + metal + "\"/></bsdf>").type,
              MaterialType::Conductor);
  m = bsdf(R"(<bsdf type="conductor"><rgb name="eta" value="0.2, 0.9, 1.1"/><rgb name="k" value="3.9, 2.4, 2.1"/>
                <rgb name="specular_reflectance" value="0.9"/></bsdf>)");
  EXPECT_EQ(m.type, MaterialType::Conductor);
  EXPECT_EQ(m.eta, Vec3(0.2f, 0.9f, 1.1f));
  EXPECT_EQ(m.k, Vec3(3.9f, 2.4f, 2.1f));
  EXPECT_EQ(m.specular, Vec3(0.9f));
  m = bsdf(R"(<bsdf type="roughconductor"><string name="material" value="Cu"/><float name="alpha" value="0.3"/>
                <string name="distribution" value="ggx"/></bsdf>)");
  EXPECT_EQ(m.type, MaterialType::RoughConductor);
  EXPECT_FLOAT_EQ(m.roughness, 0.3f);
  EXPECT_EQ(m.distribution, MicrofacetDistribution::GGX);
  expectVec(m.eta, Vec3(0.20044f, 0.92403f, 1.1022f));
  m = bsdf(R"(<bsdf type="roughconductor"/>)");
  EXPECT_EQ(m.distribution, MicrofacetDistribution::Beckmann);
  EXPECT_FLOAT_EQ(m.roughness, 0.1f);
  EXPECT_EQ(m.eta, Vec3(0.0f));
  EXPECT_EQ(m.k, Vec3(1.0f));
  EXPECT_NE(errorOf(xmlScene(R"(<shape type="rectangle"><bsdf type="roughconductor"><float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.3"/></bsdf></shape>)"))
                .find("anisotropic"),
            std::string::npos);
  EXPECT_NE(errorOf(xmlScene(R"(<shape type="rectangle"><bsdf type="conductor"><string name="material" value="Unobtainium"/></bsdf></shape>)"))
                .find("Unobtainium"),
            std::string::npos);
}

TEST(MitsubaBsdf, PlasticsWithMitsubasDefaults) {
  Material m = bsdf(R"(<bsdf type="plastic"/>)");  // polypropylene in air, diffuse 0.5, linear
  EXPECT_EQ(m.type, MaterialType::Plastic);
  EXPECT_FLOAT_EQ(m.ior, 1.49f / 1.000277f);
  EXPECT_EQ(m.albedo, Vec3(0.5f));
  EXPECT_EQ(m.specular, Vec3(1.0f));
  EXPECT_FALSE(m.coatNonlinear);
  EXPECT_FALSE(m.twoSided);
  m = bsdf(R"(<bsdf type="roughplastic"><rgb name="diffuse_reflectance" value="0.1, 0.2, 0.3"/>)"
           R"(<float name="alpha" value="0.3"/><boolean name="nonlinear" value="true"/><float name="int_ior" value="1.6"/></bsdf>)");
  EXPECT_EQ(m.type, MaterialType::RoughPlastic);
  EXPECT_EQ(m.albedo, Vec3(0.1f, 0.2f, 0.3f));
  EXPECT_FLOAT_EQ(m.roughness, 0.3f);
  EXPECT_EQ(m.distribution, MicrofacetDistribution::Beckmann);  // Mitsuba's default
  EXPECT_TRUE(m.coatNonlinear);
  EXPECT_FLOAT_EQ(m.ior, 1.6f / 1.000277f);
  const std::string wrong = errorOf(xmlScene(R"(<shape type="rectangle"><bsdf type="plastic"><texture type="bitmap" name="reflectance"/></bsdf></shape>)"));
  EXPECT_NE(wrong.find("must be its 'diffuse_reflectance'"), std::string::npos) << wrong;
}

TEST(MitsubaBsdf, UnsupportedPluginsAndParametersNameElementAndLine) {
  const std::string principled = errorOf(xmlScene("\n\n<bsdf type=\"principled\" id=\"p\"/>" + kRect));
  EXPECT_NE(principled.find("test.xml: line 11: <bsdf type=\"principled\" id=\"p\">: unsupported BSDF plugin 'principled'"),
            std::string::npos)
      << principled;
  EXPECT_NE(errorOf(xmlScene(R"(<shape type="rectangle"><bsdf type="blendbsdf"/></shape>)")).find("'blendbsdf'"), std::string::npos);
  const std::string param = errorOf(xmlScene("<shape type=\"rectangle\"><bsdf type=\"diffuse\">\n<float name=\"roughness\" value=\"1\"/></bsdf></shape>"));
  EXPECT_NE(param.find("unsupported parameter 'roughness' of bsdf 'diffuse'"), std::string::npos) << param;
  EXPECT_NE(param.find("line 10"), std::string::npos) << param;
  EXPECT_NE(errorOf(xmlScene(R"(<shape type="cylinder"/>)")).find("unsupported shape plugin 'cylinder'"), std::string::npos);
  EXPECT_NE(errorOf(xmlScene(kRect + R"(<emitter type="spot"/>)")).find("unsupported emitter plugin 'spot'"), std::string::npos);
  EXPECT_NE(errorOf(xmlScene(kRect + R"(<medium type="homogeneous"/>)")).find("medium"), std::string::npos);
  // Malformed XML: the parser's message with the line.
  const std::string bad = errorOf("<scene version=\"3.0.0\">\n<shape type=\"cube\">\n</scene>\n");
  EXPECT_NE(bad.find("test.xml: line 3: malformed XML"), std::string::npos) << bad;
  EXPECT_NE(errorOf("<shapes/>").find("root element must be <scene>"), std::string::npos);
  EXPECT_NE(errorOf("<scene><shape type=\"cube\"/></scene>").find("version"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// One-sided BSDFs

TEST(MitsubaOneSided, BsdfIsBlackFromBehindUnlessTwoSided) {
  Material m;
  m.albedo = Vec3(0.5f);
  m.twoSided = false;
  const Vec3 front(0.0f, 0.6f, 0.8f), back(0.0f, 0.6f, -0.8f), other(0.3f, 0.0f, std::sqrt(0.91f));
  EXPECT_GT(bsdfEval(m, front, other).x, 0.0f);
  EXPECT_EQ(bsdfEval(m, back, -other), Vec3(0.0f));
  EXPECT_EQ(bsdfPdf(m, back, -other), 0.0f);
  BsdfSample bs;
  EXPECT_FALSE(bsdfSample(m, back, 0.5f, Vec2(0.3f, 0.7f), bs));
  EXPECT_TRUE(bsdfSample(m, front, 0.5f, Vec2(0.3f, 0.7f), bs));
  m.type = MaterialType::Mirror;
  DeltaLobe lobes[2];
  EXPECT_EQ(bsdfDeltaLobes(m, back, lobes), 0);
  EXPECT_EQ(bsdfDeltaLobes(m, front, lobes), 1);
  m.twoSided = true;
  EXPECT_EQ(bsdfDeltaLobes(m, back, lobes), 1);
  // A dielectric is two-sided by its model whatever the flag says.
  m.type = MaterialType::Dielectric;
  m.twoSided = false;
  EXPECT_EQ(bsdfDeltaLobes(m, back, lobes), 2);
}

TEST(MitsubaOneSided, JsonScenesSayItWithTwoSided) {
  const auto material = [](const std::string& extra) {
    const Scene s = parseScene(R"({"camera": {"position": [0, 0, -5], "target": [0, 0, 0]},
        "materials": {"m": {"type": "lambertian", "albedo": 0.5)" + extra + R"(}},
        "shapes": [{"type": "quad", "material": "m", "vertices": [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]}],
        "lights": [{"type": "point", "position": [0, 0, -2], "intensity": 1}]})",
                               "t.json", ".");
    return s.materials[0];
  };
  EXPECT_TRUE(material("").twoSided);  // voxcone's default: both sides
  EXPECT_FALSE(material(R"(, "two_sided": false)").twoSided);
  EXPECT_THROW(material(R"(, "two_sided": 1)"), SceneError);
}

/// A 6 x 6 diffuse quad at z = 0 facing +z, camera and point light both at `side` (+1: in front).
Scene lonelyQuad(bool twoSided, float side) {
  const std::string quadBsdf = twoSided ? R"(<bsdf type="twosided"><bsdf type="diffuse"><rgb name="reflectance" value="0.8"/></bsdf></bsdf>)"
                                        : R"(<bsdf type="diffuse"><rgb name="reflectance" value="0.8"/></bsdf>)";
  const std::string z = std::to_string(5.0f * side), lz = std::to_string(2.0f * side);
  const std::string sensor = R"(<sensor type="perspective"><float name="fov" value="40"/>
      <transform name="to_world"><lookat origin="0.3, 0.2, )" + z + R"(" target="0, 0, 0" up="0, 1, 0"/></transform>
      <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/></film>
      <sampler type="ldsampler"><integer name="sample_count" value="16"/></sampler></sensor>
      <emitter type="point"><point name="position" x="0" y="0" z=")" + lz + R"("/><rgb name="intensity" value="10"/></emitter>)";
  return parse(xmlScene(R"(<shape type="rectangle"><transform name="to_world"><scale value="3"/></transform>)" + quadBsdf + "</shape>", sensor));
}

TEST(MitsubaOneSided, QuadSeenFromBehindIsBlackInEveryMethod) {
  for (const char* method : {"path", "whitted", "pm", "voxcone"}) {
    const Scene front = lonelyQuad(false, 1.0f), back = lonelyQuad(false, -1.0f), backTwo = lonelyQuad(true, -1.0f);
    const nlohmann::json options = nlohmann::json::object();
    RenderSettings r = front.render;
    r.photons = 20000;
    const Vec3 f = test::imageMean(test::renderWith(front, method, r, options).image);
    const Vec3 b = test::imageMean(test::renderWith(back, method, r, options).image);
    const Vec3 b2 = test::imageMean(test::renderWith(backTwo, method, r, options).image);
    EXPECT_GT(f.x, 0.05f) << method;
    EXPECT_EQ(b, Vec3(0.0f)) << method << ": one-sided quad lit and seen from behind";
    // Two-sided, the back is the front's mirror image: the same light at the same distance.
    EXPECT_NEAR(b2.x / f.x, 1.0f, 0.02f) << method;
  }
}

// ---------------------------------------------------------------------------------------------
// Emitters

TEST(MitsubaEmitters, AreaInAShapeAndPointLights) {
  const Scene s = parse(xmlScene(R"(
    <shape type="rectangle"><bsdf type="diffuse"><rgb name="reflectance" value="0"/></bsdf>
      <emitter type="area"><rgb name="radiance" value="1, 2, 3"/></emitter></shape>
    <emitter type="point"><transform name="to_world"><translate x="4" y="5" z="6"/></transform>
      <spectrum name="intensity" value="7"/></emitter>)"));
  const Material& m = s.materials[s.triMaterial[0]];
  EXPECT_EQ(m.emission, Vec3(1, 2, 3));
  EXPECT_FALSE(m.twoSidedEmission);  // Mitsuba's area emitter is one-sided
  ASSERT_EQ(s.pointLights.size(), 2u);  // kSensor's and this one
  EXPECT_EQ(s.pointLights[1].position, Vec3(4, 5, 6));
  EXPECT_EQ(s.pointLights[1].intensity, Vec3(7.0f));
  EXPECT_EQ(s.pointLights[0].position, Vec3(0, 0, -5));
  EXPECT_NE(errorOf(xmlScene(kRect + R"(<emitter type="area"/>)")).find("nested in a <shape>"), std::string::npos);
  EXPECT_NE(errorOf(xmlScene(R"(<shape type="rectangle"><emitter type="spot"/></shape>)")).find("'spot'"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// Conversion and the canonical scene

/// Triangles as position triples with their material, in scene order.
struct Tri {
  Vec3 p[3];
  const Material* m;
};
std::vector<Tri> trianglesOf(const Scene& s) {
  std::vector<Tri> out;
  for (size_t t = 0; t < s.triangleCount(); ++t) {
    const UVec3& tr = s.triangles[t];
    out.push_back({{s.positions[tr.x], s.positions[tr.y], s.positions[tr.z]}, &s.materials[s.triMaterial[t]]});
  }
  return out;
}

void expectSameMaterial(const Material& a, const Material& b) {
  EXPECT_EQ(a.name, b.name);
  EXPECT_EQ(a.type, b.type);
  EXPECT_EQ(a.albedo, b.albedo);
  EXPECT_EQ(a.emission, b.emission);
  EXPECT_EQ(a.twoSided, b.twoSided);
  EXPECT_EQ(a.twoSidedEmission, b.twoSidedEmission);
  if (!a.isDiffuse()) {
    EXPECT_EQ(a.specular, b.specular);
    EXPECT_EQ(a.ior, b.ior);
    EXPECT_EQ(a.eta, b.eta);
    EXPECT_EQ(a.k, b.k);
    EXPECT_EQ(a.roughness, b.roughness);
    EXPECT_EQ(a.distribution, b.distribution);
  }
}

class MitsubaConvert : public test::TempDirTest {};

TEST_F(MitsubaConvert, JsonToXmlToJsonGivesTheSameScene) {
  const Scene json = test::cornellBox();
  writeMitsubaScene(json, path("cb.xml"));
  const Scene xml = loadScene(path("cb.xml"));
  writeJsonScene(xml, path("back.json"));
  const Scene back = loadScene(path("back.json"));
  for (const Scene* s : {&xml, &back}) {
    const std::vector<Tri> a = trianglesOf(json), b = trianglesOf(*s);
    ASSERT_EQ(a.size(), b.size());
    for (size_t t = 0; t < a.size(); ++t) {
      for (int k = 0; k < 3; ++k) EXPECT_EQ(a[t].p[k], b[t].p[k]) << "triangle " << t;  // bit for bit
      expectSameMaterial(*a[t].m, *b[t].m);
    }
    EXPECT_EQ(s->camera.position(), json.camera.position());
    EXPECT_EQ(s->camera.target(), json.camera.target());
    EXPECT_EQ(s->camera.up(), json.camera.up());
    EXPECT_EQ(s->camera.fovYDeg(), json.camera.fovYDeg());
    EXPECT_EQ(s->render.width, json.render.width);
    EXPECT_EQ(s->render.height, json.render.height);
    EXPECT_EQ(s->render.spp, json.render.spp);
    EXPECT_EQ(s->render.maxDepth, json.render.maxDepth);
    EXPECT_EQ(s->render.seed, json.render.seed);
    EXPECT_EQ(s->render.method, json.render.method);
    EXPECT_EQ(s->render.sampler, json.render.sampler);
    EXPECT_EQ(s->render.photons, json.render.photons);
    EXPECT_EQ(s->pointLights.size(), json.pointLights.size());
  }
}

TEST_F(MitsubaConvert, WhatMitsubaCannotSayIsAnError) {
  Scene s = test::cornellBox();
  s.materials[0].type = MaterialType::OrenNayar;
  try {
    writeMitsubaScene(s, path("x.xml"));
    ADD_FAILURE() << "oren_nayar was written";
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("oren_nayar"), std::string::npos) << e.what();
  }
  s = test::cornellBox();
  for (Material& m : s.materials) m.twoSidedEmission = m.isEmissive();
  EXPECT_THROW(writeMitsubaScene(s, path("y.xml")), SceneError);
}

TEST(MitsubaCornellBox, XmlHasTheJsonScenesTrianglesMaterialsAndCamera) {
  const Scene json = test::cornellBox();
  const Scene xml = loadScene(test::sourceDir() + "/data/scenes/cornell-box.xml");
  const std::vector<Tri> a = trianglesOf(json), b = trianglesOf(xml);
  ASSERT_EQ(a.size(), b.size());
  for (size_t t = 0; t < a.size(); ++t) {
    EXPECT_EQ(a[t].m->name, b[t].m->name) << t;
    EXPECT_EQ(a[t].m->albedo, b[t].m->albedo) << t;
    EXPECT_EQ(a[t].m->emission, b[t].m->emission) << t;
    if (a[t].m->isEmissive()) {
      // The light: a rectangle there, a quad in the JSON; same plane, normal and area.
      EXPECT_FLOAT_EQ(triNormal(xml, t).y, -1.0f);
      EXPECT_NEAR(xml.triangleArea(uint32_t(t)), 130.0f * 105.0f / 2.0f, 0.05f);
      for (int k = 0; k < 3; ++k) EXPECT_NEAR(b[t].p[k].y, 548.7f, 1e-4f);
      continue;
    }
    EXPECT_TRUE(b[t].m->twoSided);
    for (int k = 0; k < 3; ++k) EXPECT_EQ(a[t].p[k], b[t].p[k]) << "triangle " << t << " vertex " << k;
  }
  EXPECT_EQ(xml.camera.position(), json.camera.position());
  EXPECT_EQ(xml.camera.target(), json.camera.target());
  EXPECT_EQ(xml.camera.fovYDeg(), json.camera.fovYDeg());
  EXPECT_EQ(xml.render.width, 256);
  EXPECT_EQ(xml.render.spp, 16);
  EXPECT_EQ(xml.render.maxDepth, json.render.maxDepth);
  EXPECT_EQ(xml.render.method, "path");
}

/// Largest |luminance ratio - 1| over the 8 x 8 cells of `a` against `b`, and a's relMSE.
struct RegionFigures {
  double maxDeviation = 0.0;
  double relMse = 0.0;
};
RegionFigures regionFigures(const Image& a, const Image& b) {
  RegionFigures f;
  for (const RegionError& cell : regionErrors(a, b, 8)) {
    const double ratio = luminance(Vec3(cell.meanTest)) / luminance(Vec3(cell.meanReference));
    f.maxDeviation = std::max(f.maxDeviation, std::abs(ratio - 1.0));
  }
  f.relMse = compareImages(a, b).relMse;
  return f;
}

/// The XML and the JSON cornell-box rendered alike with `method` (seed 0), and the JSON one
/// again with seed 1: the XML must differ from the JSON no more than the method's own noise.
struct CornellComparison {
  RegionFigures xmlVsJson, seedVsSeed;
};
CornellComparison compareCornell(const std::string& method, int res, int spp, uint64_t photons = 0) {
  const Scene json = test::cornellBox();
  const Scene xml = loadScene(test::sourceDir() + "/data/scenes/cornell-box.xml");
  RenderSettings r = json.render;
  r.width = r.height = res;
  r.spp = spp;
  r.photons = photons;
  const Image a = test::renderWith(xml, method, r).image;
  const Image b = test::renderWith(json, method, r).image;
  r.seed = 1;
  const Image c = test::renderWith(json, method, r).image;
  CornellComparison out{regionFigures(a, b), regionFigures(c, b)};
  std::printf("[ cornell-box xml vs json, %s %dx%d %d spp ] max region deviation %.4f, relMSE %.3g "
              "(json seed 1 vs 0: %.4f, %.3g)\n",
              method.c_str(), res, res, spp, out.xmlVsJson.maxDeviation, out.xmlVsJson.relMse, out.seedVsSeed.maxDeviation,
              out.seedVsSeed.relMse);
  return out;
}

TEST(MitsubaCornellBox, XmlRendersAsTheJsonSceneRegionByRegionWithPath) {
  // 64 x 64 at 256 spp, 8 x 8 cells of 8 x 8 pixels. The scenes differ only in the light's
  // triangle split and so in which points light sampling draws: the difference is noise, no
  // more than a second seed's. Measured: largest cell deviation 2.3%, relMSE 8.4e-5 (seed
  // against seed: 4.2%, 7.5e-4; one seed for both scenes keeps every path but its light
  // samples alike, hence the smaller relMSE). The bound can fail: the XML with its red wall 5%
  // darker put the red wall's cells 5.5% low.
  const CornellComparison c = compareCornell("path", 64, 256);
  EXPECT_LT(c.xmlVsJson.maxDeviation, 0.03);
  EXPECT_LT(c.xmlVsJson.relMse, 2e-4);
  EXPECT_LT(c.xmlVsJson.maxDeviation, 1.5 * c.seedVsSeed.maxDeviation);
  EXPECT_LT(c.xmlVsJson.relMse, 1.5 * c.seedVsSeed.relMse);
}

TEST(MitsubaCornellBox, XmlRendersAsTheJsonSceneRegionByRegionWithVoxcone) {
  // voxcone's default method at 64 x 64, 64 spp, 200,000 photons: its photons and voxels follow
  // the light's sampling too. Measured: largest cell deviation 6.3%, relMSE 1.3e-4 (seed
  // against seed: 24%, 1.2e-3); 5.3% before the photons' light choice was stratified (each
  // photon's choice now follows its index, so the two splits of the light pair photons
  // differently), 2.5% when this test was written.
  const CornellComparison c = compareCornell("voxcone", 64, 64, 200000);
  EXPECT_LT(c.xmlVsJson.maxDeviation, 0.08);
  EXPECT_LT(c.xmlVsJson.relMse, 1e-3);
  EXPECT_LT(c.xmlVsJson.maxDeviation, 1.5 * c.seedVsSeed.maxDeviation);
  EXPECT_LT(c.xmlVsJson.relMse, 1.5 * c.seedVsSeed.relMse);
}

}  // namespace
}  // namespace voxcone

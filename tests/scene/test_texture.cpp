// Image textures: the bilinear lookup and its (u, v) convention by hand, 8-bit files decoded
// from sRGB (a hand-computed code), a checker's mean on a plane under a constant sky equal to its
// mean albedo (and each quadrant its own texel) in path, whitted and voxcone, OBJ `vt` + `map_Kd`
// and PLY `u v` against the JSON quad, Mitsuba's bitmap, the loaders' errors, and the JSON and
// XML writers' round trip.

#include "voxcone/core/error.h"
#include "voxcone/image/image_io.h"
#include "voxcone/image/metrics.h"
#include "voxcone/scene/mitsuba.h"
#include "voxcone/scene/scene.h"
#include "voxcone/scene/texture.h"

#include "../support/render_helpers.h"
#include "../support/report.h"
#include "../support/temp_dir.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <string>
#include <vector>

namespace voxcone {
namespace {

using test::renderWith;
using test::expectVecNear;
using test::report;


double lum(const DVec3& v) { return 0.2126 * v.x + 0.7152 * v.y + 0.0722 * v.z; }

/// 2 x 2 texels: top row red-ish 0.8 / green 0.2, bottom row blue 0.5 / grey 0.1.
const Vec3 kTopLeft(0.8f, 0.1f, 0.1f), kTopRight(0.1f, 0.6f, 0.1f), kBottomLeft(0.1f, 0.1f, 0.5f), kBottomRight(0.1f);

Texture quadrants() { return Texture(2, 2, {kTopLeft, kTopRight, kBottomLeft, kBottomRight}); }

TEST(Texture, BilinearLookupFollowsTheConvention) {
  const Texture t = quadrants();
  // Texel centres: u = (i + 0.5) / 2, v = 1 - (j + 0.5) / 2.
  float worst = 0.0f;  // of the 1e-6 checks
  worst = std::max(worst, expectVecNear(t.lookup(Vec2(0.25f, 0.75f)), kTopLeft, 1e-6f, "top left"));
  worst = std::max(worst, expectVecNear(t.lookup(Vec2(0.75f, 0.75f)), kTopRight, 1e-6f, "top right"));
  worst = std::max(worst, expectVecNear(t.lookup(Vec2(0.25f, 0.25f)), kBottomLeft, 1e-6f, "bottom left"));
  worst = std::max(worst, expectVecNear(t.lookup(Vec2(0.75f, 0.25f)), kBottomRight, 1e-6f, "bottom right"));
  // Halfway between the two top texels; the corner (0, 0) is the mean of all four (repeat).
  worst = std::max(worst, expectVecNear(t.lookup(Vec2(0.5f, 0.75f)), 0.5f * (kTopLeft + kTopRight), 1e-6f, "between"));
  worst = std::max(worst, expectVecNear(t.lookup(Vec2(0.0f, 0.0f)), t.mean(), 1e-6f, "corner"));
  // Repeat: whole periods, negative ones included, change nothing.
  const float repeat = expectVecNear(t.lookup(Vec2(3.25f, -1.75f)), kBottomLeft, 1e-5f, "repeat");
  worst = std::max(worst, expectVecNear(t.mean(), 0.25f * (kTopLeft + kTopRight + kBottomLeft + kBottomRight), 1e-6f,
                                        "mean"));
  report("worst lookup error", worst, 1e-6);
  report("repeat lookup error", repeat, 1e-5);
  EXPECT_THROW(Texture(2, 2, {kTopLeft}), Error);
  EXPECT_THROW(Texture(1, 1, {Vec3(-0.1f)}), Error);
}

class TextureFiles : public test::TempDirTest {
protected:
  /// quadrants() as a 2 x 2 EXR (linear) named `name`.
  std::string writeQuadrants(const std::string& name = "tex.exr") const {
    Image img(2, 2);
    img.at(0, 0) = kTopLeft;
    img.at(1, 0) = kTopRight;
    img.at(0, 1) = kBottomLeft;
    img.at(1, 1) = kBottomRight;
    const std::string file = path(name);
    writeImage(file, img, nlohmann::json::object());
    return file;
  }
  std::string writeText(const std::string& name, const std::string& text) const {
    std::ofstream(path(name), std::ios::binary) << text;
    return path(name);
  }
};

TEST_F(TextureFiles, EightBitFilesAreDecodedFromSrgb) {
  // 0.2158605 encodes to code 128 (writeImage rounds the sRGB curve to 8 bits); read back as a
  // texture it is ((128 / 255 + 0.055) / 1.055)^2.4 = 0.215861, by hand.
  Image img(1, 1, Vec3(0.2158605f, 0.0f, 1.0f));
  writeImage(path("t.png"), img, nlohmann::json::object());
  const Texture t = loadTexture(path("t.png"));
  report("decoded texel error", expectVecNear(t.texel(0, 0), Vec3(0.215861f, 0.0f, 1.0f), 2e-6f), 2e-6);
  EXPECT_EQ(t.file, path("t.png"));
  try {
    loadTexture(path("missing.png"));
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("missing.png"), std::string::npos) << e.what();
  }
}

/// A 2 x 2 quad at z = 0 (x, y in [-1, 1]) facing +z, textured `albedo_texture` `file`, seen head
/// on from +z (up +y), under a constant sky of radiance 1: every point sees the whole upper
/// hemisphere (nothing else in the scene), so it shows albedo(uv) exactly.
std::string skyQuadScene(const std::string& shape, const std::string& material) {
  return R"({
    "camera": {"position": [0, 0, 4], "target": [0, 0, 0], "up": [0, 1, 0], "fov_y_deg": 28.0724869},
    "render": {"width": 16, "height": 16, "spp": 16, "max_depth": 4},
    "materials": {"tex": )" + material + R"(},
    "shapes": [)" + shape + R"(],
    "lights": [{"type": "environment", "radiance": [1, 1, 1]}]})";
}

const char* kQuad = R"({"type": "quad", "material": "tex", "vertices": [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]})";

/// Each 8 x 8 quadrant's mean.
std::vector<DVec3> quadrantMeans(const Image& img) {
  std::vector<DVec3> out;
  for (int qy = 0; qy < 2; ++qy)
    for (int qx = 0; qx < 2; ++qx) {
      DVec3 s(0.0);
      for (int y = 0; y < 8; ++y)
        for (int x = 0; x < 8; ++x) s += DVec3(img.at(qx * 8 + x, qy * 8 + y));
      out.push_back(s / 64.0);
    }
  return out;
}

TEST_F(TextureFiles, ACheckerUnderAConstantSkyShowsItsAlbedoInEveryMethod) {
  // The camera's view is exactly the quad (fov 2 atan(1 / 4)), the pixel grid aligned with the
  // texels: the image's top rows are the texture's top row, and each point shows its bilinear
  // albedo. Along each axis a texel's weight falls from 1 at its centre to 1/2 at the quadrant's
  // edges (the neighbour, by repeat, the other texel on both sides): 3/4 on average over its
  // quadrant. So a quadrant's mean is 9/16 its texel, 3/16 each neighbour in x and in y, 1/16
  // the diagonal one; the image's mean is the texture's.
  writeQuadrants();
  const Scene loaded = parseScene(skyQuadScene(kQuad, R"({"type": "lambertian", "albedo_texture": "tex.exr"})"), "quad",
                                  path(""));
  ASSERT_EQ(loaded.textures.size(), 1u);
  const Texture t = quadrants();
  const auto expected = [&](const Vec3& own, const Vec3& side, const Vec3& vertical, const Vec3& diagonal) {
    return DVec3(0.5625f * own + 0.1875f * side + 0.1875f * vertical + 0.0625f * diagonal);
  };
  const std::vector<DVec3> want = {expected(kTopLeft, kTopRight, kBottomLeft, kBottomRight),
                                   expected(kTopRight, kTopLeft, kBottomRight, kBottomLeft),
                                   expected(kBottomLeft, kBottomRight, kTopLeft, kTopRight),
                                   expected(kBottomRight, kBottomLeft, kTopRight, kTopLeft)};
  // The quadrant channel nearest its bound, and the worst mean, over the methods.
  double worstErr = -1.0, worstTol = 1.0, worstMean = -1.0;
  std::string worstAt, worstMeanAt;
  for (const char* method : {"whitted", "path", "voxcone"}) {
    const Image img = renderWith(loaded, method, loaded.render).image;
    const std::vector<DVec3> got = quadrantMeans(img);
    for (size_t q = 0; q < 4; ++q)
      for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(got[q][c], want[q][c], 0.03 * want[q][c] + 0.002) << method << " quadrant " << q << " channel " << c;
    for (size_t q = 0; q < 4; ++q)
      for (int c = 0; c < 3; ++c) {
        const double err = std::fabs(got[q][c] - want[q][c]), tol = 0.03 * want[q][c] + 0.002;
        if (err / tol > worstErr / worstTol) {
          worstErr = err;
          worstTol = tol;
          worstAt = std::string(method) + " quadrant " + std::to_string(q) + " channel " + std::to_string(c);
        }
      }
    DVec3 mean(0.0);
    for (const DVec3& g : got) mean += g / 4.0;
    EXPECT_NEAR(lum(mean), lum(DVec3(t.mean())), 0.02 * lum(DVec3(t.mean()))) << method;
    const double meanOff = std::fabs(lum(mean) / lum(DVec3(t.mean())) - 1.0);
    if (meanOff > worstMean) {
      worstMean = meanOff;
      worstMeanAt = method;
    }
  }
  report("quadrant error nearest its bound (" + worstAt + ")", worstErr, worstTol);
  report("mean luminance relative error (" + worstMeanAt + ")", worstMean, 0.02);
}

TEST_F(TextureFiles, ObjTexcoordsAndMapKdMatchTheJsonQuad) {
  writeQuadrants();
  writeText("q.mtl", "newmtl checker\nKd 0.3 0.3 0.3\nmap_Kd tex.exr\n");
  // The quad as an OBJ with vt (v0..v3 at (0,0), (1,0), (1,1), (0,1)) and normals, so corners
  // are split by (v, vt, vn).
  writeText("q.obj",
            "mtllib q.mtl\nv -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\n"
            "usemtl checker\nf 1/1/1 2/2/1 3/3/1\nf 1/1/1 3/3/1 4/4/1\n");
  const Scene json = parseScene(skyQuadScene(kQuad, R"({"type": "lambertian", "albedo_texture": "tex.exr"})"), "q",
                                path(""));
  const Scene obj = parseScene(R"({
    "camera": {"position": [0, 0, 4], "target": [0, 0, 0], "up": [0, 1, 0], "fov_y_deg": 28.0724869},
    "render": {"width": 16, "height": 16, "spp": 16, "max_depth": 4},
    "materials": {},
    "shapes": [{"type": "mesh", "file": "q.obj"}],
    "lights": [{"type": "environment", "radiance": [1, 1, 1]}]})",
                               "q", path(""));
  ASSERT_EQ(obj.uvs.size(), obj.positions.size());
  ASSERT_EQ(obj.textures.size(), 1u);
  // map_Kd replaces Kd (pbrt, Blender): the albedo is the texture alone.
  EXPECT_EQ(obj.materials[obj.triMaterial[0]].albedo, Vec3(1.0f));
  const Image a = renderWith(json, "whitted", json.render).image;
  const Image b = renderWith(obj, "whitted", obj.render).image;
  const double objRelMse = compareImages(b, a).relMse;
  report("OBJ vs JSON relMSE", objRelMse, 1e-3);
  EXPECT_LT(objRelMse, 1e-3);

  // The same quad as an ASCII PLY with u v.
  writeText("q.ply",
            "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
            "property float u\nproperty float v\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n"
            "-1 -1 0 0 0\n1 -1 0 1 0\n1 1 0 1 1\n-1 1 0 0 1\n3 0 1 2\n3 0 2 3\n");
  const Scene ply = parseScene(skyQuadScene(R"({"type": "mesh", "file": "q.ply", "material": "tex"})",
                                            R"({"type": "lambertian", "albedo_texture": "tex.exr"})"),
                               "q", path(""));
  ASSERT_EQ(ply.uvs.size(), 4u);
  EXPECT_EQ(ply.uvs[2], Vec2(1.0f, 1.0f));
  const Image c = renderWith(ply, "whitted", ply.render).image;
  const double plyRelMse = compareImages(c, a).relMse;
  report("PLY vs JSON relMSE", plyRelMse, 1e-3);
  EXPECT_LT(plyRelMse, 1e-3);
}

TEST_F(TextureFiles, MitsubaBitmapOnARectangle) {
  writeQuadrants();
  // Mitsuba's rectangle has uv ((x + 1) / 2, (y + 1) / 2) with v = 0 its bitmap's top row: seen
  // from +z with +y up, its image is upside down against the JSON quad's. Turning it by 180
  // degrees about x (y -> -y, facing -z) and looking from -z with up -y... simpler: a scale of
  // -1 in y mirrors it back, and flip_normals keeps its face towards the camera.
  const std::string xml = R"(<scene version="3.0.0">
  <sensor type="perspective">
    <float name="fov" value="28.0724869"/><string name="fov_axis" value="y"/>
    <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
    <sampler type="independent"><integer name="sample_count" value="16"/></sampler>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/></film>
  </sensor>
  <emitter type="constant"><rgb name="radiance" value="1, 1, 1"/></emitter>
  <shape type="rectangle">
    <transform name="to_world"><scale y="-1"/></transform>
    <bsdf type="diffuse"><texture type="bitmap" name="reflectance"><string name="filename" value="tex.exr"/></texture></bsdf>
  </shape>
</scene>)";
  const Scene mts = parseMitsubaScene(xml, "m.xml", path(""));
  ASSERT_EQ(mts.textures.size(), 1u);
  const Scene json = parseScene(skyQuadScene(kQuad, R"({"type": "lambertian", "albedo_texture": "tex.exr"})"), "q",
                                path(""));
  RenderSettings s = json.render;
  const Image a = renderWith(json, "whitted", s).image;
  const Image b = renderWith(mts, "whitted", s).image;
  const double relMse = compareImages(b, a).relMse;
  report("Mitsuba vs JSON relMSE", relMse, 1e-3);
  EXPECT_LT(relMse, 1e-3);
  // Unsupported bitmap settings are errors, not a different image.
  std::string raw = xml;
  raw.replace(raw.find("<string name=\"filename\""), 0, "<boolean name=\"raw\" value=\"true\"/>");
  EXPECT_THROW(parseMitsubaScene(raw, "m.xml", path("")), Error);
  std::string checker = xml;
  checker.replace(checker.find("type=\"bitmap\""), 13, "type=\"checkerboard\"");
  EXPECT_THROW(parseMitsubaScene(checker, "m.xml", path("")), Error);
}

TEST_F(TextureFiles, LoaderErrors) {
  writeQuadrants();
  const auto errorOf = [&](const std::string& shape, const std::string& material) {
    try {
      parseScene(skyQuadScene(shape, material), "s.json", path(""));
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  // A missing file names itself and the key.
  const std::string missing = errorOf(kQuad, R"({"type": "lambertian", "albedo_texture": "nope.png"})");
  EXPECT_NE(missing.find("nope.png"), std::string::npos) << missing;
  EXPECT_NE(missing.find("albedo_texture"), std::string::npos) << missing;
  // A textured material on a shape without texture coordinates (a sphere).
  const std::string noUv = errorOf(R"({"type": "sphere", "center": [0, 0, 0], "radius": 1, "material": "tex"})",
                                   R"({"type": "lambertian", "albedo_texture": "tex.exr"})");
  EXPECT_NE(noUv.find("no texture coordinates"), std::string::npos) << noUv;
  // Only diffuse materials take a texture.
  const std::string mirror = errorOf(kQuad, R"({"type": "mirror", "albedo_texture": "tex.exr"})");
  EXPECT_NE(mirror.find("albedo_texture"), std::string::npos) << mirror;
  // An OBJ whose vt index is out of range (tinyobjloader's warning, an error here).
  writeText("bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/3\n");
  const std::string badVt = errorOf(R"({"type": "mesh", "file": "bad.obj", "material": "tex"})",
                                    R"({"type": "lambertian"})");
  EXPECT_NE(badVt.find("texcoord indices out of bounds"), std::string::npos) << badVt;
}

TEST_F(TextureFiles, WritersKeepTheTextureAndTheCoordinates) {
  writeQuadrants();
  const Scene json = parseScene(skyQuadScene(kQuad, R"({"type": "lambertian", "albedo_texture": "tex.exr"})"), "q",
                                path(""));
  const Image a = renderWith(json, "whitted", json.render).image;
  writeJsonScene(json, path("out.json"));
  const Scene back = loadScene(path("out.json"));
  ASSERT_EQ(back.textures.size(), 1u);
  const double jsonRelMse = compareImages(renderWith(back, "whitted", json.render).image, a).relMse;
  report("JSON round trip relMSE", jsonRelMse, 1e-3);
  EXPECT_LT(jsonRelMse, 1e-3);
  writeMitsubaScene(json, path("out.xml"));
  const Scene xmlBack = loadMitsubaScene(path("out.xml"));
  ASSERT_EQ(xmlBack.textures.size(), 1u);
  const double xmlRelMse = compareImages(renderWith(xmlBack, "whitted", json.render).image, a).relMse;
  report("XML round trip relMSE", xmlRelMse, 1e-3);
  EXPECT_LT(xmlRelMse, 1e-3);
}

}  // namespace
}  // namespace voxcone

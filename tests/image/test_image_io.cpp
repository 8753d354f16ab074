/// \file test_image_io.cpp
/// sRGB transfer functions, EXR/PNG round trips, atomic writes and read errors.

#include "voxcone/core/error.h"
#include "voxcone/core/file_io.h"
#include "voxcone/image/image_io.h"

#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>

#include <algorithm>

#include "../support/image_errors.h"
#include "../support/temp_dir.h"
#include <nlohmann/json.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using namespace voxcone;

namespace {

/// A fresh empty directory per test, removed afterwards.
class ImageIoTest : public test::TempDirTest {
protected:
  /// Names of every entry in the test directory (hidden temporaries included).
  std::vector<std::string> entries() const {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(m_dir)) names.push_back(e.path().filename().string());
    return names;
  }
};

std::string readText(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

void writeText(const std::string& path, const std::string& text) {
  std::ofstream f(path, std::ios::binary);
  f << text;
}

bool sameBits(float a, float b) {
  uint32_t ua, ub;
  std::memcpy(&ua, &a, 4);
  std::memcpy(&ub, &b, 4);
  return ua == ub;
}

/// Image with values spanning HDR range, negatives, denormal-ish and exact-binary values.
Image testPattern(int w, int h, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  Image im(w, h);
  for (auto& p : im.pixels) p = Vec3(u(rng), u(rng) * 20.0f, u(rng) * 1e-3f);
  im.at(0, 0) = Vec3(-0.5f, 1e-30f, 65504.0f * 4.0f);
  im.at(w - 1, h - 1) = Vec3(0.0f, 1.0f, 0.1f);
  return im;
}

}  // namespace

TEST(ImageSrgb, KnownValues) {
  EXPECT_EQ(linearToSrgb(0.0f), 0.0f);
  EXPECT_FLOAT_EQ(linearToSrgb(1.0f), 1.0f);
  // Toe: 12.92 * 0.002 = 0.02584.
  EXPECT_FLOAT_EQ(linearToSrgb(0.002f), 0.02584f);
  // Both segments meet at linear 0.0031308 / encoded 0.04045 (IEC 61966-2-1).
  EXPECT_NEAR(linearToSrgb(0.0031308f), 0.04045f, 1e-6f);
  EXPECT_NEAR(srgbToLinear(0.04045f), 0.0031308f, 1e-7f);
  // 1.055 * 0.5^(1/2.4) - 0.055 = 0.735357; ((0.5 + 0.055) / 1.055)^2.4 = 0.214041.
  EXPECT_NEAR(linearToSrgb(0.5f), 0.7353570f, 1e-6f);
  EXPECT_NEAR(srgbToLinear(0.5f), 0.2140411f, 1e-6f);
  // 255 * 0.735357 = 187.516 -> 188; 255 * srgb(0.18) = 117.646 -> 118; 255 * srgb(0.125) = 99.086 -> 99.
  EXPECT_EQ(toSrgb8(0.5f), 188);
  EXPECT_EQ(toSrgb8(0.18f), 118);
  EXPECT_EQ(toSrgb8(0.125f), 99);
  // Clamping: negatives and NaN to 0, above 1 to 255.
  EXPECT_EQ(toSrgb8(-1.0f), 0);
  EXPECT_EQ(toSrgb8(std::numeric_limits<float>::quiet_NaN()), 0);
  EXPECT_EQ(toSrgb8(7.0f), 255);
  EXPECT_EQ(toSrgb8(std::numeric_limits<float>::infinity()), 255);
}

TEST(ImageSrgb, RoundTripEvery8BitCode) {
  for (int c = 0; c <= 255; ++c) EXPECT_EQ(toSrgb8(srgbToLinear(float(c) / 255.0f)), c) << "code " << c;
}

TEST(ImageSrgb, RoundTripFloat) {
  for (int i = 0; i <= 10000; ++i) {
    const float v = float(i) / 10000.0f;
    EXPECT_NEAR(srgbToLinear(linearToSrgb(v)), v, 1e-6f + 2e-6f * v) << v;
    EXPECT_NEAR(linearToSrgb(srgbToLinear(v)), v, 1e-6f + 2e-6f * v) << v;
  }
}

TEST_F(ImageIoTest, ExrRoundTripBitExactWithMetadata) {
  const Image im = testPattern(13, 7, 1);
  const nlohmann::json meta = {{"seed", 42}, {"settings", {{"spp", 16}, {"method", "path"}}}};
  const std::string file = path("out.exr");
  writeExr(file, im, meta);

  const Image back = readImage(file);
  ASSERT_EQ(back.width, im.width);
  ASSERT_EQ(back.height, im.height);
  for (size_t i = 0; i < im.pixels.size(); ++i)
    for (int c = 0; c < 3; ++c) ASSERT_TRUE(sameBits(back.pixels[i][c], im.pixels[i][c])) << i << " " << c;

  // Metadata attributes, read with OpenImageIO directly.
  auto in = OIIO::ImageInput::open(file);
  ASSERT_TRUE(in);
  const OIIO::ImageSpec& spec = in->spec();
  EXPECT_EQ(spec.format, OIIO::TypeDesc::FLOAT);
  EXPECT_EQ(spec.nchannels, 3);
  EXPECT_EQ(nlohmann::json::parse(spec.get_string_attribute("voxcone:metadata")), meta);
  in->close();
  EXPECT_EQ(entries(), std::vector<std::string>{"out.exr"});
}

TEST_F(ImageIoTest, ExrMetadataIsTypedAttributes) {
  const nlohmann::json meta = {{"seed", 42},
                               {"big_seed", uint64_t(1) << 40},
                               {"partial", true},
                               {"settings", {{"spp", 16}, {"method", "path"}, {"integrator", {{"cone_angle", 0.5}}}}},
                               {"command_line", {"voxcone", "render", "a b.json"}},
                               {"nothing", nullptr}};
  const std::string file = path("typed.exr");
  writeExr(file, Image(2, 2, Vec3(0.5f)), meta);
  auto in = OIIO::ImageInput::open(file);
  ASSERT_TRUE(in);
  const OIIO::ImageSpec& spec = in->spec();
  const auto type = [&](const char* name) {
    const OIIO::ParamValue* p = spec.find_attribute(name);
    return p ? p->type() : OIIO::TypeUnknown;
  };
  EXPECT_EQ(type("voxcone:seed"), OIIO::TypeInt);
  EXPECT_EQ(spec.get_int_attribute("voxcone:seed"), 42);
  EXPECT_EQ(type("voxcone:partial"), OIIO::TypeInt);
  EXPECT_EQ(spec.get_int_attribute("voxcone:partial"), 1);
  EXPECT_EQ(type("voxcone:settings.spp"), OIIO::TypeInt);
  EXPECT_EQ(spec.get_int_attribute("voxcone:settings.spp"), 16);
  EXPECT_EQ(type("voxcone:settings.method"), OIIO::TypeString);
  EXPECT_EQ(spec.get_string_attribute("voxcone:settings.method"), "path");  // not "\"path\""
  EXPECT_EQ(type("voxcone:settings.integrator.cone_angle"), OIIO::TypeFloat);
  EXPECT_FLOAT_EQ(spec.get_float_attribute("voxcone:settings.integrator.cone_angle"), 0.5f);
  // Past int's range a number is its exact decimal text; an array its JSON; null nothing.
  EXPECT_EQ(spec.get_string_attribute("voxcone:big_seed"), "1099511627776");
  EXPECT_EQ(nlohmann::json::parse(spec.get_string_attribute("voxcone:command_line")), meta["command_line"]);
  EXPECT_EQ(spec.find_attribute("voxcone:nothing"), nullptr);
  EXPECT_EQ(spec.find_attribute("voxcone:settings"), nullptr);
}

TEST_F(ImageIoTest, ExrLayersRoundTripAndReadImageTakesRgbByName) {
  const Image im = testPattern(5, 3, 2);
  ImageLayer albedo{"albedo", {"Albedo.R", "Albedo.G", "Albedo.B"}, {}};
  ImageLayer depth{"depth", {"Z"}, {}};
  for (size_t i = 0; i < im.pixels.size(); ++i) {
    for (int c = 0; c < 3; ++c) albedo.values.push_back(0.1f * float(c + 1) + float(i));
    depth.values.push_back(100.0f + float(i));
  }
  const std::string file = path("layers.exr");
  writeExr(file, im, nullptr, nullptr, {albedo, depth});
  auto in = OIIO::ImageInput::open(file);
  ASSERT_TRUE(in);
  const OIIO::ImageSpec spec = in->spec();
  ASSERT_EQ(spec.nchannels, 7);
  std::vector<float> all(im.pixels.size() * 7);
  ASSERT_TRUE(in->read_image(0, 0, 0, 7, OIIO::TypeDesc::FLOAT, all.data()));
  in->close();
  const auto channel = [&](const std::string& n) {
    const auto it = std::find(spec.channelnames.begin(), spec.channelnames.end(), n);
    EXPECT_NE(it, spec.channelnames.end()) << n;
    return int(it - spec.channelnames.begin());
  };
  for (size_t i = 0; i < im.pixels.size(); ++i) {
    for (int c = 0; c < 3; ++c) {
      EXPECT_EQ(all[i * 7 + size_t(channel(std::string(1, "RGB"[c])))], im.pixels[i][c]);
      EXPECT_EQ(all[i * 7 + size_t(channel(std::string("Albedo.") + "RGB"[c]))], albedo.values[i * 3 + size_t(c)]);
    }
    EXPECT_EQ(all[i * 7 + size_t(channel("Z"))], depth.values[i]);
  }
  const Image back = readImage(file);
  for (size_t i = 0; i < im.pixels.size(); ++i)
    for (int c = 0; c < 3; ++c) ASSERT_TRUE(sameBits(back.pixels[i][c], im.pixels[i][c])) << i << " " << c;
  // A layer of the wrong size is refused before anything is written.
  depth.values.pop_back();
  EXPECT_THROW(writeExr(path("bad.exr"), im, nullptr, nullptr, {depth}), ImageError);
  EXPECT_FALSE(fs::exists(path("bad.exr")));
}

TEST_F(ImageIoTest, PngCarriesMetadataAsText) {
  const nlohmann::json meta = {{"voxcone_version", "9.8.7"}, {"method", "voxcone"}, {"settings", {{"spp", 4}}}};
  const std::string file = path("meta.png");
  writePng(file, Image(3, 2, Vec3(0.25f)), nullptr, meta);
  auto in = OIIO::ImageInput::open(file);
  ASSERT_TRUE(in);
  EXPECT_EQ(in->spec().get_string_attribute("Software"), "voxcone 9.8.7");
  EXPECT_EQ(in->spec().get_string_attribute("voxcone:method"), "voxcone");
  EXPECT_EQ(in->spec().get_string_attribute("voxcone:settings.spp"), "4");
}

TEST_F(ImageIoTest, ExrOverwritesExisting) {
  const std::string file = path("out.exr");
  writeExr(file, Image(4, 4, Vec3(1.0f)), nlohmann::json::object());
  writeExr(file, Image(2, 3, Vec3(0.25f)), nlohmann::json());
  const Image back = readImage(file);
  ASSERT_EQ(back.width, 2);
  ASSERT_EQ(back.height, 3);
  EXPECT_EQ(back.at(1, 2), Vec3(0.25f));
}

TEST_F(ImageIoTest, PngRoundTripWithin8BitQuantization) {
  Image im = testPattern(17, 9, 2);
  for (auto& p : im.pixels) p = glm::min(p, Vec3(1.5f));
  const std::string file = path("out.png");
  writePng(file, im);

  // The file holds exactly toSrgb8 of every value.
  auto in = OIIO::ImageInput::open(file);
  ASSERT_TRUE(in);
  EXPECT_EQ(in->spec().format, OIIO::TypeDesc::UINT8);
  ASSERT_EQ(in->spec().nchannels, 3);
  std::vector<uint8_t> codes(im.pixels.size() * 3);
  ASSERT_TRUE(in->read_image(0, 0, 0, 3, OIIO::TypeDesc::UINT8, codes.data()));
  in->close();
  for (size_t i = 0; i < im.pixels.size(); ++i)
    for (int c = 0; c < 3; ++c) ASSERT_EQ(int(codes[3 * i + c]), toSrgb8(im.pixels[i][c])) << i << " " << c;

  // Read back as linear: the decoded code, i.e. the original within half a code step.
  const Image back = readImage(file);
  ASSERT_EQ(back.width, im.width);
  ASSERT_EQ(back.height, im.height);
  for (size_t i = 0; i < im.pixels.size(); ++i) {
    for (int c = 0; c < 3; ++c) {
      const float v = im.pixels[i][c];
      EXPECT_NEAR(back.pixels[i][c], srgbToLinear(float(toSrgb8(v)) / 255.0f), 1e-6f);
      EXPECT_EQ(toSrgb8(back.pixels[i][c]), toSrgb8(v));
      const float clamped = std::min(std::max(v, 0.0f), 1.0f);
      EXPECT_NEAR(linearToSrgb(back.pixels[i][c]), linearToSrgb(clamped), 0.5f / 255.0f + 1e-6f);
    }
  }
}

TEST_F(ImageIoTest, ReadGreyAndAlphaPng) {
  // 16-bit grey + alpha PNG written with OpenImageIO: grey replicated, alpha dropped (colour not
  // premultiplied by it: pixel 0 has alpha 0 and stays white), decoded.
  const std::string file = path("grey.png");
  {
    OIIO::ImageSpec spec(2, 1, 2, OIIO::TypeDesc::UINT16);
    auto out = OIIO::ImageOutput::create(file);
    ASSERT_TRUE(out);
    ASSERT_TRUE(out->open(file, spec));
    const uint16_t px[4] = {65535, 0, 32768, 65535};
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT16, px));
    out->close();
  }
  const Image im = readImage(file);
  ASSERT_EQ(im.width, 2);
  ASSERT_EQ(im.height, 1);
  EXPECT_NEAR(im.at(0, 0).x, 1.0f, 1e-6f);
  const float grey = srgbToLinear(32768.0f / 65535.0f);
  EXPECT_NEAR(im.at(1, 0).x, grey, 1e-6f);
  EXPECT_EQ(im.at(1, 0).x, im.at(1, 0).y);
  EXPECT_EQ(im.at(1, 0).x, im.at(1, 0).z);
}

TEST_F(ImageIoTest, WriteImageByExtension) {
  const Image im(3, 2, Vec3(0.5f));
  writeImage(path("a.exr"), im, {{"k", 1}});
  writeImage(path("b.PNG"), im, {{"k", 1}});
  EXPECT_EQ(readImage(path("a.exr")).at(2, 1), Vec3(0.5f));
  EXPECT_EQ(toSrgb8(readImage(path("b.PNG")).at(2, 1).y), 188);
  EXPECT_THROW(writeImage(path("c.jpg"), im, nullptr), ImageError);
  EXPECT_THROW(writeImage(path("noext"), im, nullptr), ImageError);
  EXPECT_FALSE(fs::exists(path("c.jpg")));
  EXPECT_THROW(writeExr(path("empty.exr"), Image(), nullptr), ImageError);
  EXPECT_FALSE(fs::exists(path("empty.exr")));
  EXPECT_EQ(entries().size(), 2u);
}

TEST_F(ImageIoTest, WriteToMissingDirectoryThrowsAndLeavesNothing) {
  const Image im(2, 2, Vec3(0.5f));
  const std::string missing = path("no/such/dir");
  EXPECT_THROW(writeExr(missing + "/x.exr", im, nullptr), ImageError);
  EXPECT_THROW(writePng(missing + "/x.png", im), ImageError);
  EXPECT_THROW(writeJsonAtomic(missing + "/x.json", {{"a", 1}}), Error);
  EXPECT_THROW(writeFileAtomic(missing + "/x.txt", [](const std::string&) {}), Error);
  EXPECT_FALSE(fs::exists(path("no")));
  EXPECT_TRUE(entries().empty());
  try {
    writeExr(missing + "/x.exr", im, nullptr);
  } catch (const ImageError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(missing), std::string::npos) << msg;
    EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
  }
}

TEST_F(ImageIoTest, AtomicWriteTemporaryNaming) {
  std::string seen;
  writeFileAtomic(path("data.bin"), [&](const std::string& tmp) {
    seen = tmp;
    writeText(tmp, "new");
  });
  EXPECT_EQ(readText(path("data.bin")), "new");
  const fs::path tmp(seen);
  EXPECT_EQ(tmp.parent_path(), m_dir);
  const std::string name = tmp.filename().string();
  EXPECT_EQ(name.rfind(".data.tmp-" + std::to_string(::getpid()) + "-", 0), 0u) << name;
  EXPECT_EQ(tmp.extension(), ".bin");
  EXPECT_FALSE(fs::exists(tmp));
  EXPECT_EQ(entries(), std::vector<std::string>{"data.bin"});
}

TEST_F(ImageIoTest, StaleTemporariesOfDeadProcessesAreRemovedOnTheNextWrite) {
  // A process killed with SIGKILL mid-write leaves its temporary; the next write of that target
  // removes it. Temporaries of live processes (pid 1, this one) and of other targets stay.
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) ::_exit(0);
  ASSERT_EQ(::waitpid(child, nullptr, 0), child);
  const std::string dead = ".data.tmp-" + std::to_string(child) + "-0.bin";
  const std::string live = ".data.tmp-1-0.bin", mine = ".data.tmp-" + std::to_string(::getpid()) + "-99.bin";
  const std::string other = ".other.tmp-" + std::to_string(child) + "-0.bin";
  for (const std::string& n : {dead, live, mine, other}) writeText(path(n), "stale");
  writeFileAtomic(path("data.bin"), [&](const std::string& tmp) { writeText(tmp, "new"); });
  EXPECT_FALSE(fs::exists(path(dead)));
  for (const std::string& n : {live, mine, other}) EXPECT_TRUE(fs::exists(path(n))) << n;
}

TEST_F(ImageIoTest, AtomicWriterThrowLeavesNoFile) {
  // New target: neither the target nor the temporary may remain.
  EXPECT_THROW(writeFileAtomic(path("new.txt"),
                               [](const std::string& tmp) {
                                 writeText(tmp, "partial");
                                 throw std::runtime_error("writer failed");
                               }),
               std::runtime_error);
  EXPECT_TRUE(entries().empty());

  // Existing target: kept intact.
  writeText(path("old.txt"), "old contents");
  EXPECT_THROW(writeFileAtomic(path("old.txt"),
                               [](const std::string& tmp) {
                                 writeText(tmp, "partial");
                                 throw std::runtime_error("writer failed");
                               }),
               std::runtime_error);
  EXPECT_EQ(readText(path("old.txt")), "old contents");
  EXPECT_EQ(entries(), std::vector<std::string>{"old.txt"});

  // A writer that creates nothing: the rename fails with an Error, target still intact.
  EXPECT_THROW(writeFileAtomic(path("old.txt"), [](const std::string&) {}), Error);
  EXPECT_EQ(readText(path("old.txt")), "old contents");
  EXPECT_EQ(entries(), std::vector<std::string>{"old.txt"});
}

TEST_F(ImageIoTest, OutputSetAppearsWholeOrNotAtAll) {
  Image img(4, 3);
  img.pixels.assign(12, Vec3(0.25f, 0.5f, 1.0f));
  // Committed: all three, nothing else; the sidecar renamed last.
  {
    OutputSet set;
    writeExr(path("a.exr"), img, {{"k", 1}}, &set);
    writePng(path("a.png"), img, &set);
    writeJsonAtomic(path("a.json"), {{"done", true}}, &set);
    EXPECT_EQ(entries().size(), 3u);  // the temporaries alone so far
    for (const char* f : {"a.exr", "a.png", "a.json"}) EXPECT_FALSE(fs::exists(path(f))) << f;
    set.commit(path("a.json"));
  }
  std::vector<std::string> names = entries();
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"a.exr", "a.json", "a.png"}));
  EXPECT_EQ(readImage(path("a.exr")).pixels, img.pixels);
  fs::remove(path("a.exr"));
  fs::remove(path("a.png"));
  fs::remove(path("a.json"));

  // A write that fails after others succeeded: none of the set appears, no temporary stays.
  {
    OutputSet set;
    writeExr(path("b.exr"), img, {}, &set);
    EXPECT_THROW(set.add(path("b.png"),
                         [](const std::string& tmp) {
                           writeText(tmp, "partial");
                           throw std::runtime_error("writer failed");
                         }),
                 std::runtime_error);
  }
  EXPECT_TRUE(entries().empty());

  // A rename that fails (the sidecar's path is a non-empty folder): the files renamed before
  // it go too.
  fs::create_directories(path("c.json") + "/inside");
  {
    OutputSet set;
    writeExr(path("c.exr"), img, {}, &set);
    writeJsonAtomic(path("c.json"), {{"done", true}}, &set);
    EXPECT_THROW(set.commit(path("c.json")), Error);
  }
  EXPECT_EQ(entries(), std::vector<std::string>{"c.json"});  // the folder alone
}

TEST_F(ImageIoTest, WriteJsonAtomic) {
  const nlohmann::json value = {{"a", 1}, {"b", {1, 2, 3}}};
  writeJsonAtomic(path("x.json"), {{"old", true}});
  writeJsonAtomic(path("x.json"), value);
  const std::string text = readText(path("x.json"));
  EXPECT_EQ(nlohmann::json::parse(text), value);
  EXPECT_EQ(text, value.dump(2) + "\n");
  EXPECT_EQ(entries(), std::vector<std::string>{"x.json"});
}

TEST_F(ImageIoTest, ReadMissingOrGarbageThrows) {
  using test::expectOneLineImageError;
  expectOneLineImageError(path("missing.exr"));
  writeText(path("garbage.exr"), "this is not an OpenEXR file\nsecond line\n");
  expectOneLineImageError(path("garbage.exr"));
  writeText(path("garbage.png"), std::string(100, '\x7f'));
  expectOneLineImageError(path("garbage.png"));
  writeText(path("empty.png"), "");
  expectOneLineImageError(path("empty.png"));
  expectOneLineImageError(m_dir.string());
}

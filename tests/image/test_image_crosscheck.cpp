/// \file test_image_crosscheck.cpp
/// voxcone's own readers and writers (OpenEXR, libpng, libjpeg) against OpenImageIO, which the
/// executable once used for its image files and which only the tests link now: files written by
/// voxcone read by OpenImageIO, files written by OpenImageIO (and by libpng and libjpeg with
/// layouts OpenImageIO does not write) read by readImage exactly as OpenImageIO 2.4 read them.
/// Truncated and foreign files give one-line ImageErrors.

#include "voxcone/core/error.h"
#include "voxcone/image/image_io.h"

#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>
#include <png.h>
#include <zlib.h>
// jpeglib.h needs FILE and size_t declared first.
#include <cstdio>
#include <jpeglib.h>

#include "../support/image_errors.h"
#include "../support/temp_dir.h"

#include <algorithm>
#include <cmath>
#include <csetjmp>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using namespace voxcone;

namespace {

class ImageCrossCheck : public test::TempDirTest {};

/// readImage as it was with OpenImageIO (the code before voxcone read files itself): the
/// reference every file below is read against, bit for bit.
Image readWithOiio(const std::string& path) {
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);
  auto in = OIIO::ImageInput::open(path, &config);
  if (!in) throw ImageError(path + ": OpenImageIO cannot read it: " + OIIO::geterror());
  const OIIO::ImageSpec& spec = in->spec();
  const int nch = spec.nchannels;
  const size_t npix = static_cast<size_t>(spec.width) * static_cast<size_t>(spec.height);
  std::vector<float> buf(npix * static_cast<size_t>(nch));
  if (!in->read_image(0, 0, 0, nch, OIIO::TypeDesc::FLOAT, buf.data()))
    throw ImageError(path + ": OpenImageIO cannot read pixels: " + in->geterror());
  in->close();
  const std::string colorSpace = spec.get_string_attribute("oiio:ColorSpace");
  const bool integer = spec.format.basetype == OIIO::TypeDesc::UINT8 ||
                       spec.format.basetype == OIIO::TypeDesc::UINT16 ||
                       spec.format.basetype == OIIO::TypeDesc::INT8 || spec.format.basetype == OIIO::TypeDesc::INT16;
  const auto startsWith = [](const std::string& s, const char* p) {
    return s.size() >= std::strlen(p) && strncasecmp(s.c_str(), p, std::strlen(p)) == 0;
  };
  enum class Decode { None, Srgb, Gamma } decode = Decode::None;
  float gamma = 1.0f;
  if (integer) {
    if (colorSpace.empty() || startsWith(colorSpace, "srgb")) {
      decode = Decode::Srgb;
    } else if (startsWith(colorSpace, "gamma")) {
      gamma = spec.get_float_attribute("oiio:Gamma", 2.2f);
      decode = gamma > 0.0f ? Decode::Gamma : Decode::Srgb;
    }
  }
  auto toLinear = [&](float v) {
    switch (decode) {
      case Decode::Srgb: return srgbToLinear(v);
      case Decode::Gamma: return std::pow(std::max(v, 0.0f), gamma);
      default: return v;
    }
  };
  int rgb[3] = {0, 1, 2};
  if (nch > 3) {
    const auto& names = spec.channelnames;
    const auto find = [&](const char* n) { return int(std::find(names.begin(), names.end(), n) - names.begin()); };
    const int r = find("R"), g = find("G"), b = find("B");
    if (r < nch && g < nch && b < nch) rgb[0] = r, rgb[1] = g, rgb[2] = b;
  }
  Image image(spec.width, spec.height);
  image.displayEncoded = integer;
  for (size_t i = 0; i < npix; ++i) {
    const float* p = &buf[i * static_cast<size_t>(nch)];
    if (nch < 3) image.pixels[i] = Vec3(toLinear(p[0]));
    else image.pixels[i] = Vec3(toLinear(p[rgb[0]]), toLinear(p[rgb[1]]), toLinear(p[rgb[2]]));
  }
  return image;
}

bool sameBits(float a, float b) {
  uint32_t ua, ub;
  std::memcpy(&ua, &a, 4);
  std::memcpy(&ub, &b, 4);
  return ua == ub;
}

/// readImage and the OpenImageIO reference agree bit for bit (NaNs included).
void expectSameAsOiio(const std::string& file) {
  SCOPED_TRACE(file);
  const Image ref = readWithOiio(file);
  const Image ours = readImage(file);
  ASSERT_EQ(ours.width, ref.width);
  ASSERT_EQ(ours.height, ref.height);
  EXPECT_EQ(ours.displayEncoded, ref.displayEncoded);
  size_t bad = 0;
  for (size_t i = 0; i < ref.pixels.size(); ++i)
    for (int c = 0; c < 3; ++c)
      if (!sameBits(ours.pixels[i][c], ref.pixels[i][c]) && bad++ < 5)
        ADD_FAILURE() << "pixel " << i << " channel " << c << ": " << ours.pixels[i][c] << " vs OpenImageIO "
                      << ref.pixels[i][c];
  EXPECT_EQ(bad, 0u);
}

/// Write `values` (nch per pixel, of `type`) with OpenImageIO; `setup` adjusts the spec.
template <typename T>
void writeWithOiio(const std::string& file, int w, int h, const std::vector<std::string>& names, OIIO::TypeDesc type,
                   const std::vector<T>& values, const std::function<void(OIIO::ImageSpec&)>& setup = {}) {
  OIIO::ImageSpec spec(w, h, int(names.size()), type);
  spec.channelnames = names;
  if (setup) setup(spec);
  auto out = OIIO::ImageOutput::create(file);
  ASSERT_TRUE(out) << OIIO::geterror();
  ASSERT_TRUE(out->open(file, spec)) << out->geterror();
  ASSERT_TRUE(out->write_image(OIIO::BaseTypeFromC<T>::value, values.data())) << out->geterror();
  ASSERT_TRUE(out->close());
}

template <typename T>
std::vector<T> ramp(size_t n, unsigned seed, double scale) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<T> v(n);
  for (auto& x : v) x = T(u(rng) * scale);
  return v;
}

/// A PNG written with libpng's low-level API: any colour type and bit depth, palette, tRNS,
/// gAMA, interlacing. `rows` holds the packed rows as PNG stores them (16-bit big-endian).
struct PngLayout {
  int colorType = PNG_COLOR_TYPE_RGB, bitDepth = 8;
  bool interlaced = false;
  double gamma = 0.0;  ///< file gamma (gAMA), 0: none
  bool srgb = false;
  std::vector<png_color> palette;
  std::vector<png_byte> trns;
};

bool writePngRaw(const std::string& file, int w, int h, const PngLayout& l, const std::vector<png_byte>& data) {
  FILE* f = std::fopen(file.c_str(), "wb");
  if (!f) return false;
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png_create_info_struct(png);
  const size_t rowBytes = data.size() / size_t(h);
  bool ok = false;
  if (!setjmp(png_jmpbuf(png))) {
    png_init_io(png, f);
    png_set_IHDR(png, info, w, h, l.bitDepth, l.colorType, l.interlaced ? PNG_INTERLACE_ADAM7 : PNG_INTERLACE_NONE,
                 PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    if (!l.palette.empty()) png_set_PLTE(png, info, l.palette.data(), int(l.palette.size()));
    if (!l.trns.empty()) png_set_tRNS(png, info, l.trns.data(), int(l.trns.size()), nullptr);
    if (l.gamma > 0.0) png_set_gAMA(png, info, l.gamma);
    if (l.srgb) png_set_sRGB(png, info, PNG_sRGB_INTENT_PERCEPTUAL);
    png_write_info(png, info);
    const int passes = png_set_interlace_handling(png);
    for (int p = 0; p < passes; ++p)
      for (int y = 0; y < h; ++y) png_write_row(png, const_cast<png_bytep>(data.data() + size_t(y) * rowBytes));
    png_write_end(png, info);
    ok = true;
  }
  png_destroy_write_struct(&png, &info);
  std::fclose(f);
  return ok;
}

/// A CMYK JPEG written with libjpeg (OpenImageIO writes none).
void writeCmykJpeg(const std::string& file, int w, int h, const std::vector<unsigned char>& cmyk) {
  FILE* f = std::fopen(file.c_str(), "wb");
  ASSERT_TRUE(f);
  jpeg_compress_struct c;
  jpeg_error_mgr err;
  c.err = jpeg_std_error(&err);
  jpeg_create_compress(&c);
  jpeg_stdio_dest(&c, f);
  c.image_width = JDIMENSION(w);
  c.image_height = JDIMENSION(h);
  c.input_components = 4;
  c.in_color_space = JCS_CMYK;
  jpeg_set_defaults(&c);
  jpeg_set_colorspace(&c, JCS_YCCK);
  jpeg_start_compress(&c, TRUE);
  for (int y = 0; y < h; ++y) {
    JSAMPROW row = const_cast<JSAMPROW>(cmyk.data() + size_t(y) * size_t(w) * 4);
    jpeg_write_scanlines(&c, &row, 1);
  }
  jpeg_finish_compress(&c);
  jpeg_destroy_compress(&c);
  std::fclose(f);
}

std::string readBytes(const std::string& file) {
  std::ifstream f(file, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
}

Image pattern(int w, int h, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  Image im(w, h);
  for (auto& p : im.pixels) p = Vec3(u(rng) * 1.2f, u(rng) * 30.0f, u(rng) * 1e-3f);
  im.at(0, 0) = Vec3(-0.5f, 1e-30f, 65504.0f * 4.0f);
  return im;
}

}  // namespace

TEST_F(ImageCrossCheck, VoxconeExrReadByOiio) {
  const Image im = pattern(19, 11, 3);
  ImageLayer normal{"normal", {"Ns.X", "Ns.Y", "Ns.Z"}, {}};
  ImageLayer depth{"depth", {"Z"}, {}};
  for (size_t i = 0; i < im.pixels.size(); ++i) {
    for (int c = 0; c < 3; ++c) normal.values.push_back(float(c) - 0.25f * float(i));
    depth.values.push_back(1.0f / float(i + 1));
  }
  const nlohmann::json meta = {{"voxcone_version", "1.2.3"},
                               {"seed", uint64_t(1) << 40},
                               {"settings", {{"spp", 16}, {"method", "path"}, {"cone", 0.125}}},
                               {"partial", false}};
  const std::string file = path("v.exr");
  writeExr(file, im, meta, nullptr, {normal, depth});
  auto in = OIIO::ImageInput::open(file);
  ASSERT_TRUE(in);
  const OIIO::ImageSpec spec = in->spec();
  EXPECT_EQ(spec.format, OIIO::TypeDesc::FLOAT);
  ASSERT_EQ(spec.nchannels, 7);
  EXPECT_EQ(spec.get_string_attribute("compression"), "rle");
  EXPECT_FALSE(spec.get_string_attribute("DateTime").empty());  // capDate, as OpenImageIO wrote it
  EXPECT_EQ(nlohmann::json::parse(spec.get_string_attribute("voxcone:metadata")), meta);
  EXPECT_EQ(spec.find_attribute("voxcone:seed")->type(), OIIO::TypeString);
  EXPECT_EQ(spec.get_string_attribute("voxcone:seed"), "1099511627776");
  EXPECT_EQ(spec.find_attribute("voxcone:settings.spp")->type(), OIIO::TypeInt);
  EXPECT_EQ(spec.find_attribute("voxcone:partial")->type(), OIIO::TypeInt);
  EXPECT_EQ(spec.get_int_attribute("voxcone:partial", -1), 0);
  EXPECT_EQ(spec.find_attribute("voxcone:settings.cone")->type(), OIIO::TypeFloat);
  EXPECT_EQ(spec.get_float_attribute("voxcone:settings.cone"), 0.125f);
  EXPECT_EQ(spec.get_string_attribute("voxcone:settings.method"), "path");
  std::vector<float> all(im.pixels.size() * 7);
  ASSERT_TRUE(in->read_image(0, 0, 0, 7, OIIO::TypeDesc::FLOAT, all.data()));
  const auto channel = [&](const std::string& n) {
    return size_t(std::find(spec.channelnames.begin(), spec.channelnames.end(), n) - spec.channelnames.begin());
  };
  for (size_t i = 0; i < im.pixels.size(); ++i) {
    for (int c = 0; c < 3; ++c) {
      EXPECT_TRUE(sameBits(all[i * 7 + channel(std::string(1, "RGB"[c]))], im.pixels[i][c]));
      EXPECT_EQ(all[i * 7 + channel(std::string("Ns.") + "XYZ"[c])], normal.values[i * 3 + size_t(c)]);
    }
    EXPECT_EQ(all[i * 7 + channel("Z")], depth.values[i]);
  }
  expectSameAsOiio(file);
}

TEST_F(ImageCrossCheck, VoxconePngReadByOiio) {
  Image im = pattern(23, 9, 4);
  const nlohmann::json meta = {{"voxcone_version", "1.2.3"}, {"seed", 7}, {"settings", {{"cone", 0.5}}}};
  const std::string file = path("v.png");
  writePng(file, im, nullptr, meta);
  auto in = OIIO::ImageInput::open(file);
  ASSERT_TRUE(in);
  const OIIO::ImageSpec spec = in->spec();
  EXPECT_EQ(spec.format, OIIO::TypeDesc::UINT8);
  ASSERT_EQ(spec.nchannels, 3);
  EXPECT_EQ(spec.get_string_attribute("oiio:ColorSpace"), "sRGB");
  EXPECT_EQ(spec.get_string_attribute("Software"), "voxcone 1.2.3");
  EXPECT_EQ(spec.get_string_attribute("voxcone:seed"), "7");
  EXPECT_EQ(spec.get_string_attribute("voxcone:settings.cone"), "0.5");
  EXPECT_EQ(spec.get_string_attribute("voxcone:voxcone_version"), "1.2.3");
  std::vector<uint8_t> codes(im.pixels.size() * 3);
  ASSERT_TRUE(in->read_image(0, 0, 0, 3, OIIO::TypeDesc::UINT8, codes.data()));
  for (size_t i = 0; i < im.pixels.size(); ++i)
    for (int c = 0; c < 3; ++c) ASSERT_EQ(int(codes[3 * i + size_t(c)]), toSrgb8(im.pixels[i][c]));
  expectSameAsOiio(file);
}

TEST_F(ImageCrossCheck, OiioPngsReadIdentically) {
  const int w = 13, h = 7;
  const size_t n = size_t(w) * h;
  writeWithOiio(path("rgb8.png"), w, h, {"R", "G", "B"}, OIIO::TypeDesc::UINT8, ramp<uint8_t>(n * 3, 1, 255.99));
  writeWithOiio(path("rgb16.png"), w, h, {"R", "G", "B"}, OIIO::TypeDesc::UINT16, ramp<uint16_t>(n * 3, 2, 65535.99));
  writeWithOiio(path("grey8.png"), w, h, {"Y"}, OIIO::TypeDesc::UINT8, ramp<uint8_t>(n, 3, 255.99));
  writeWithOiio(path("greyalpha16.png"), w, h, {"Y", "A"}, OIIO::TypeDesc::UINT16, ramp<uint16_t>(n * 2, 4, 65535.99));
  // Unassociated alpha kept: colour not divided or multiplied by it.
  writeWithOiio(path("rgba8.png"), w, h, {"R", "G", "B", "A"}, OIIO::TypeDesc::UINT8, ramp<uint8_t>(n * 4, 5, 255.99),
                [](OIIO::ImageSpec& s) { s.attribute("oiio:UnassociatedAlpha", 1); });
  // gAMA chunks: 1.8 (a power law), 1.0 (linear: no decoding).
  writeWithOiio(path("gamma18.png"), w, h, {"R", "G", "B"}, OIIO::TypeDesc::UINT8, ramp<uint8_t>(n * 3, 6, 255.99),
                [](OIIO::ImageSpec& s) { s.attribute("oiio:ColorSpace", "Gamma1.8"); });
  writeWithOiio(path("linear16.png"), w, h, {"R", "G", "B"}, OIIO::TypeDesc::UINT16,
                ramp<uint16_t>(n * 3, 7, 65535.99), [](OIIO::ImageSpec& s) { s.attribute("oiio:ColorSpace", "Linear"); });
  for (const char* f : {"rgb8.png", "rgb16.png", "grey8.png", "greyalpha16.png", "rgba8.png", "gamma18.png",
                        "linear16.png"})
    expectSameAsOiio(path(f));
  // The gAMA rules, against known values: 1.8 decodes as v^1.8, linear not at all.
  const Image g = readImage(path("gamma18.png"));
  const std::vector<uint8_t> codes = ramp<uint8_t>(n * 3, 6, 255.99);
  EXPECT_FLOAT_EQ(g.pixels[0].x, std::pow(float(codes[0]) / 255.0f, 1.8f));
  EXPECT_TRUE(g.displayEncoded);
}

TEST_F(ImageCrossCheck, LibpngLayoutsReadIdentically) {
  const int w = 11, h = 5;
  // Palette, with and without tRNS; 1-bit grey; interlaced RGB; 16-bit RGBA; gAMA 2.2 and 2.345;
  // an sRGB chunk; 4-bit palette.
  PngLayout pal;
  pal.colorType = PNG_COLOR_TYPE_PALETTE;
  for (int i = 0; i < 16; ++i) pal.palette.push_back({png_byte(i * 16), png_byte(255 - i * 7), png_byte(i * i)});
  std::vector<png_byte> idx(size_t(w) * h);
  for (size_t i = 0; i < idx.size(); ++i) idx[i] = png_byte(i % 16);
  ASSERT_TRUE(writePngRaw(path("palette.png"), w, h, pal, idx));
  PngLayout palTrns = pal;
  palTrns.trns = {0, 128, 255, 7};
  ASSERT_TRUE(writePngRaw(path("palette_trns.png"), w, h, palTrns, idx));
  PngLayout pal4 = pal;
  pal4.bitDepth = 4;
  std::vector<png_byte> idx4(size_t((w + 1) / 2) * h);
  for (size_t i = 0; i < idx4.size(); ++i) idx4[i] = png_byte((i * 37) & 0xff);
  ASSERT_TRUE(writePngRaw(path("palette4.png"), w, h, pal4, idx4));
  PngLayout grey1;
  grey1.colorType = PNG_COLOR_TYPE_GRAY;
  grey1.bitDepth = 1;
  std::vector<png_byte> bits(size_t((w + 7) / 8) * h);
  for (size_t i = 0; i < bits.size(); ++i) bits[i] = png_byte(0xa5 ^ i);
  ASSERT_TRUE(writePngRaw(path("grey1.png"), w, h, grey1, bits));
  PngLayout inter;
  inter.interlaced = true;
  const std::vector<png_byte> rgb = ramp<png_byte>(size_t(w) * h * 3, 8, 255.99);
  ASSERT_TRUE(writePngRaw(path("interlaced.png"), w, h, inter, rgb));
  PngLayout rgba16;
  rgba16.colorType = PNG_COLOR_TYPE_RGB_ALPHA;
  rgba16.bitDepth = 16;
  ASSERT_TRUE(writePngRaw(path("rgba16.png"), w, h, rgba16, ramp<png_byte>(size_t(w) * h * 8, 9, 255.99)));
  PngLayout g22;
  g22.gamma = 1.0 / 2.2;
  ASSERT_TRUE(writePngRaw(path("gamma22.png"), w, h, g22, rgb));
  PngLayout odd;
  odd.gamma = 1.0 / 2.345;  // rounded to 2.35 as OpenImageIO rounds it
  ASSERT_TRUE(writePngRaw(path("gamma2345.png"), w, h, odd, rgb));
  PngLayout both;  // libpng writes gAMA and cHRM with it (an inconsistent gAMA it refuses)
  both.srgb = true;
  ASSERT_TRUE(writePngRaw(path("srgb_and_gamma.png"), w, h, both, rgb));
  for (const char* f : {"palette.png", "palette_trns.png", "palette4.png", "grey1.png", "interlaced.png",
                        "rgba16.png", "gamma22.png", "gamma2345.png", "srgb_and_gamma.png"})
    expectSameAsOiio(path(f));
}

TEST_F(ImageCrossCheck, OiioJpegsReadIdentically) {
  const int w = 29, h = 17;
  const size_t n = size_t(w) * h;
  writeWithOiio(path("rgb.jpg"), w, h, {"R", "G", "B"}, OIIO::TypeDesc::UINT8, ramp<uint8_t>(n * 3, 10, 255.99),
                [](OIIO::ImageSpec& s) { s.attribute("Compression", "jpeg:85"); });
  writeWithOiio(path("grey.jpeg"), w, h, {"Y"}, OIIO::TypeDesc::UINT8, ramp<uint8_t>(n, 11, 255.99));
  writeCmykJpeg(path("cmyk.jpg"), w, h, ramp<uint8_t>(n * 4, 12, 255.99));
  for (const char* f : {"rgb.jpg", "grey.jpeg", "cmyk.jpg"}) expectSameAsOiio(path(f));
}

TEST_F(ImageCrossCheck, OiioExrsReadIdentically) {
  const int w = 9, h = 6;
  const size_t n = size_t(w) * h;
  // Half RGB; float RGBA with layers (R, G, B found by name); 32-bit unsigned channels.
  writeWithOiio(path("half.exr"), w, h, {"R", "G", "B"}, OIIO::TypeDesc::HALF, ramp<float>(n * 3, 13, 70000.0));
  writeWithOiio(path("layers.exr"), w, h, {"R", "G", "B", "A", "diffuse.R", "diffuse.G", "diffuse.B", "Z"},
                OIIO::TypeDesc::FLOAT, ramp<float>(n * 8, 14, 4.0));
  writeWithOiio(path("uint.exr"), w, h, {"R", "G", "B"}, OIIO::TypeDesc::UINT, ramp<uint32_t>(n * 3, 15, 4.0e9));
  // Grey + alpha (Y replicated), one channel, XYZ names (first three in OpenImageIO's order),
  // unnamed layers only, a data window away from the origin, tiles.
  writeWithOiio(path("ya.exr"), w, h, {"Y", "A"}, OIIO::TypeDesc::HALF, ramp<float>(n * 2, 16, 2.0));
  writeWithOiio(path("mono.exr"), w, h, {"depth"}, OIIO::TypeDesc::FLOAT, ramp<float>(n, 17, 100.0));
  writeWithOiio(path("xyz.exr"), w, h, {"Z", "Y", "X", "W"}, OIIO::TypeDesc::FLOAT, ramp<float>(n * 4, 18, 1.0));
  writeWithOiio(path("aov.exr"), w, h, {"a.v", "b.u", "a.Blue", "a.Red", "a.Green"}, OIIO::TypeDesc::FLOAT,
                ramp<float>(n * 5, 19, 1.0));
  writeWithOiio(path("window.exr"), w, h, {"R", "G", "B"}, OIIO::TypeDesc::FLOAT, ramp<float>(n * 3, 20, 1.0),
                [](OIIO::ImageSpec& s) {
                  s.x = 3, s.y = -2;
                  s.full_x = 0, s.full_y = 0, s.full_width = 20, s.full_height = 20;
                });
  writeWithOiio(path("tiled.exr"), w, h, {"R", "G", "B"}, OIIO::TypeDesc::HALF, ramp<float>(n * 3, 21, 1.0),
                [](OIIO::ImageSpec& s) { s.tile_width = s.tile_height = 4; s.attribute("compression", "piz"); });
  for (const char* f : {"half.exr", "layers.exr", "uint.exr", "ya.exr", "mono.exr", "xyz.exr", "aov.exr",
                        "window.exr", "tiled.exr"})
    expectSameAsOiio(path(f));
  EXPECT_FALSE(readImage(path("half.exr")).displayEncoded);
}

TEST_F(ImageCrossCheck, TruncatedFilesThrowOneLineErrors) {
  const Image im = pattern(64, 48, 22);
  writeExr(path("full.exr"), im, {{"k", 1}});
  writePng(path("full.png"), im);
  const int w = 64, h = 48;
  writeWithOiio(path("full.jpg"), w, h, {"R", "G", "B"}, OIIO::TypeDesc::UINT8,
                ramp<uint8_t>(size_t(w) * h * 3, 23, 255.99));
  for (const char* ext : {"exr", "png", "jpg"}) {
    const std::string bytes = readBytes(path(std::string("full.") + ext));
    ASSERT_GT(bytes.size(), 200u);
    // Cut inside the pixel data, inside the header, after the signature alone.
    for (const size_t keep : {bytes.size() - 1, bytes.size() / 2, size_t(100), size_t(9)}) {
      const std::string cut = path("cut" + std::to_string(keep) + "." + ext);
      write("cut" + std::to_string(keep) + "." + ext, bytes.substr(0, keep));
      SCOPED_TRACE(cut);
      if (std::string(ext) == "png" && keep == bytes.size() - 1) {
        // Only IEND's CRC lost: the pixels are whole, and read as before.
        EXPECT_EQ(readImage(cut).pixels, readImage(path("full.png")).pixels);
        continue;
      }
      if (std::string(ext) == "jpg" && keep == bytes.size() - 1) continue;  // the EOI marker's last byte
      test::expectOneLineImageError(cut);
    }
    // Corrupted pixel data (bytes flipped in the second half): an error or an image, never a crash.
    std::string flipped = bytes;
    for (size_t i = bytes.size() / 2; i < bytes.size(); i += 7) flipped[i] = char(flipped[i] ^ 0x5a);
    write(std::string("flip.") + ext, flipped);
    try {
      readImage(path(std::string("flip.") + ext));
    } catch (const ImageError& e) {
      EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos);
    }
  }
}

TEST_F(ImageCrossCheck, OtherFormatsNameTheSupportedOnes) {
  writeWithOiio(path("a.tif"), 4, 4, {"R", "G", "B"}, OIIO::TypeDesc::UINT8, ramp<uint8_t>(48, 24, 255.99));
  test::expectOneLineImageError(path("a.tif"), "OpenEXR, PNG and JPEG");
  write("b.hdr", "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 1 +X 1\n\x80\x80\x80\x81");
  test::expectOneLineImageError(path("b.hdr"), "OpenEXR, PNG and JPEG");
  // A PNG named .exr is read as the PNG it is; garbage named .jpg is not a JPEG.
  writePng(path("real.png"), Image(3, 2, Vec3(0.5f)));
  fs::copy_file(path("real.png"), path("named.exr"));
  EXPECT_EQ(readImage(path("named.exr")).pixels, readImage(path("real.png")).pixels);
  write("garbage.jpg", std::string(64, 'x'));
  test::expectOneLineImageError(path("garbage.jpg"), "JPEG");
  write("tiny.png", "\x89PNG");
  test::expectOneLineImageError(path("tiny.png"));
  // A PNG header claiming 100000 x 100000 pixels in a few bytes: refused, nothing allocated.
  std::string png = readBytes(path("real.png"));
  png[16] = 0, png[17] = 1, png[18] = char(0x86), png[19] = char(0xa0);
  png[20] = 0, png[21] = 1, png[22] = char(0x86), png[23] = char(0xa0);
  const uLong crc = crc32(0, reinterpret_cast<const Bytef*>(png.data() + 12), 17);
  for (int i = 0; i < 4; ++i) png[29 + i] = char((crc >> (24 - 8 * i)) & 0xff);
  write("huge.png", png);
  test::expectOneLineImageError(path("huge.png"));
}

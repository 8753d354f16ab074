// The denoiser (denoise/denoiser.h): the .tza reader against archives written here byte by
// byte, the half floats and the transfer function against hand-computed values, the blocked,
// vectorized network against a plain loop-by-loop U-Net of random weights (a wiring error, a
// wrong concatenation order or padding shows there), the same image at any thread count; and,
// with the published weights fetched, what the network must do to renders: raise PSNR by a
// stated margin, move no 4x4 cell's mean, leave a converged image within its noise.

#include "voxcone/accel/hbvh.h"
#include "voxcone/core/error.h"
#include "voxcone/core/parallel.h"
#include "voxcone/core/rng.h"
#include "voxcone/denoise/denoiser.h"
#include "voxcone/image/metrics.h"

#include "../support/render_helpers.h"
#include "../support/test_scenes.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <tuple>
#include <vector>

namespace voxcone {
namespace {

// ---- a .tza written by hand

/// Little-endian bytes of a .tza v2 holding `tensors` (name, dims, layout, type 'f' or 'h',
/// the raw element bits), the table after the data as OIDN's writer places it.
struct RawTensor {
  std::string name;
  std::vector<uint32_t> dims;
  std::string layout;
  char type;
  std::vector<uint32_t> bits;  ///< one per element: 32 bits ('f') or the low 16 ('h')
};

void put(std::vector<uint8_t>& b, uint64_t v, int bytes) {
  for (int i = 0; i < bytes; ++i) b.push_back(uint8_t(v >> (8 * i)));
}

std::vector<uint8_t> tzaBytes(const std::vector<RawTensor>& tensors, uint16_t magic = 0x41D7, uint8_t major = 2) {
  std::vector<uint8_t> b;
  put(b, magic, 2);
  b.push_back(major);
  b.push_back(0);
  put(b, 0, 8);  // the table's offset, filled in below
  std::vector<uint64_t> offsets;
  for (const RawTensor& t : tensors) {
    while (b.size() % 64 != 0) b.push_back(0);
    offsets.push_back(b.size());
    for (uint32_t v : t.bits) put(b, v, t.type == 'h' ? 2 : 4);
  }
  const uint64_t table = b.size();
  for (int i = 0; i < 8; ++i) b[4 + size_t(i)] = uint8_t(table >> (8 * i));
  put(b, tensors.size(), 4);
  for (size_t i = 0; i < tensors.size(); ++i) {
    const RawTensor& t = tensors[i];
    put(b, t.name.size(), 2);
    b.insert(b.end(), t.name.begin(), t.name.end());
    b.push_back(uint8_t(t.dims.size()));
    for (uint32_t d : t.dims) put(b, d, 4);
    b.insert(b.end(), t.layout.begin(), t.layout.end());
    b.push_back(uint8_t(t.type));
    put(b, offsets[i], 8);
  }
  return b;
}

uint32_t floatBits(float f) {
  uint32_t u;
  std::memcpy(&u, &f, 4);
  return u;
}

TEST(Tza, ReadsFp32AndFp16TensorsAsWrittenByHand) {
  const std::vector<uint8_t> bytes = tzaBytes({
      {"conv.weight", {2, 1, 1, 2}, "oihw", 'f', {floatBits(1.5f), floatBits(-2.0f), floatBits(0.25f), floatBits(7.0f)}},
      {"conv.bias", {3}, "x", 'h', {0x3C00u, 0xC000u, 0x7BFFu}},  // 1, -2, 65504
  });
  const auto t = parseTza(bytes, "hand.tza");
  ASSERT_EQ(t.size(), 2u);
  const TzaTensor& w = t.at("conv.weight");
  EXPECT_EQ(w.dims, (std::vector<int>{2, 1, 1, 2}));
  EXPECT_EQ(w.layout, "oihw");
  EXPECT_EQ(w.values, (std::vector<float>{1.5f, -2.0f, 0.25f, 7.0f}));
  const TzaTensor& b = t.at("conv.bias");
  EXPECT_EQ(b.dims, (std::vector<int>{3}));
  EXPECT_EQ(b.values, (std::vector<float>{1.0f, -2.0f, 65504.0f}));
}

TEST(Tza, MalformedArchivesAreOneLineErrors) {
  const RawTensor good{"b", {2}, "x", 'f', {floatBits(1.0f), floatBits(2.0f)}};
  const auto errorOf = [](const std::vector<uint8_t>& bytes) {
    try {
      parseTza(bytes, "bad.tza");
    } catch (const ImageError& e) {
      const std::string what = e.what();
      EXPECT_EQ(what.find('\n'), std::string::npos) << what;
      return what;
    }
    return std::string("no error");
  };
  EXPECT_NE(errorOf(tzaBytes({good}, 0x1234)).find("bad magic"), std::string::npos);
  EXPECT_NE(errorOf(tzaBytes({good}, 0x41D7, 1)).find("version 1"), std::string::npos);
  std::vector<uint8_t> cut = tzaBytes({good});
  cut.resize(cut.size() - 3);
  EXPECT_NE(errorOf(cut).find("truncated"), std::string::npos);
  EXPECT_NE(errorOf(tzaBytes({{"b", {2}, "oi", 'f', good.bits}})).find("layout"), std::string::npos);
  EXPECT_NE(errorOf(tzaBytes({{"b", {2}, "x", 'd', good.bits}})).find("data type"), std::string::npos);
  EXPECT_NE(errorOf(tzaBytes({{"b", {4}, "x", 'f', good.bits}})).find("past the end"), std::string::npos);
  EXPECT_NE(errorOf(tzaBytes({good, good})).find("twice"), std::string::npos);
  EXPECT_NE(errorOf({0xD7}).find("truncated"), std::string::npos);
  EXPECT_THROW(readTza("/nonexistent/weights.tza"), ImageError);
}

TEST(Tza, HalfFloatsDecodeExactly) {
  EXPECT_EQ(halfToFloat(0x0000), 0.0f);
  EXPECT_TRUE(std::signbit(halfToFloat(0x8000)));
  EXPECT_EQ(halfToFloat(0x3C00), 1.0f);
  EXPECT_EQ(halfToFloat(0x3555), 0.333251953125f);
  EXPECT_EQ(halfToFloat(0xC000), -2.0f);
  EXPECT_EQ(halfToFloat(0x7BFF), 65504.0f);
  EXPECT_EQ(halfToFloat(0x0400), std::ldexp(1.0f, -14));                  // smallest normal
  EXPECT_EQ(halfToFloat(0x0001), std::ldexp(1.0f, -24));                  // smallest subnormal
  EXPECT_EQ(halfToFloat(0x03FF), std::ldexp(1023.0f, -24));               // largest subnormal
  EXPECT_EQ(halfToFloat(0x8201), -std::ldexp(513.0f, -24));
  EXPECT_EQ(halfToFloat(0x7C00), std::numeric_limits<float>::infinity());
  EXPECT_EQ(halfToFloat(0xFC00), -std::numeric_limits<float>::infinity());
  EXPECT_TRUE(std::isnan(halfToFloat(0x7E00)));
}

// ---- the transfer function and the exposure

TEST(Denoiser, PuTransferIsNormalizedContinuousAndInverted) {
  EXPECT_NEAR(Denoiser::puForward(65504.0f), 1.0f, 1e-6f);
  EXPECT_EQ(Denoiser::puForward(0.0f), 0.0f);
  // The fit's pieces meet at its knots (y0 = 1.5794576e-6, y1 = 3.22087631e-2) to 1e-3.
  for (float knot : {1.57945760e-06f, 3.22087631e-02f}) {
    const float below = Denoiser::puForward(knot * (1.0f - 1e-6f)), above = Denoiser::puForward(knot * (1.0f + 1e-6f));
    EXPECT_NEAR(below, above, 1e-3f * above) << knot;
  }
  for (float y : {1e-7f, 1e-4f, 0.01f, 0.18f, 1.0f, 12.5f, 1000.0f, 60000.0f})
    EXPECT_NEAR(Denoiser::puInverse(Denoiser::puForward(y)), y, 2e-4f * y) << y;
  // Monotone: a brighter input is never mapped lower.
  float last = -1.0f;
  for (float y = 1e-8f; y < 1e5f; y *= 1.5f) {
    EXPECT_GT(Denoiser::puForward(y), last) << y;
    last = Denoiser::puForward(y);
  }
}

TEST(Denoiser, AutoexposureIsTheKeyOverTheBlocksGeometricMean) {
  // Constant colour: 0.18 over its luminance (Rec. 709 weights as OIDN's).
  Image c(40, 24, Vec3(0.5f, 1.0f, 2.0f));
  const double lum = 0.212671 * 0.5 + 0.715160 * 1.0 + 0.072169 * 2.0;
  EXPECT_NEAR(Denoiser::autoexposure(c), 0.18 / lum, 1e-5);
  // Two 16x16 blocks of luminance 1 and 4: the geometric mean is 2.
  Image two(32, 16, Vec3(1.0f));
  for (int y = 0; y < 16; ++y)
    for (int x = 16; x < 32; ++x) two.at(x, y) = Vec3(4.0f);
  EXPECT_NEAR(Denoiser::autoexposure(two), 0.09, 1e-6);
  // Black blocks are left out; a black image is not scaled.
  two.pixels.assign(two.pixels.size(), Vec3(0.0f));
  EXPECT_EQ(Denoiser::autoexposure(two), 1.0f);
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x) two.at(x, y) = Vec3(2.0f);
  EXPECT_NEAR(Denoiser::autoexposure(two), 0.09, 1e-6);
}

// ---- the network against a plain U-Net

/// Random weights of a small U-Net with the RT network's names and wiring: odd and padded
/// channel counts (12, 3, 9 + 8) where the blocked layout must pad.
std::map<std::string, TzaTensor> randomNetwork(int inputChannels, uint64_t seed) {
  const std::vector<std::pair<std::string, int>> outs = {
      {"enc_conv0", 8},   {"enc_conv1", 8},   {"enc_conv2", 12},  {"enc_conv3", 8},  {"enc_conv4", 16}, {"enc_conv5a", 8},
      {"enc_conv5b", 16}, {"dec_conv4a", 8},  {"dec_conv4b", 16}, {"dec_conv3a", 8}, {"dec_conv3b", 8}, {"dec_conv2a", 16},
      {"dec_conv2b", 8},  {"dec_conv1a", 16}, {"dec_conv1b", 8},  {"dec_conv0", 3}};
  std::map<std::string, int> out;
  for (const auto& [n, c] : outs) out[n] = c;
  const std::map<std::string, int> in = {
      {"enc_conv0", inputChannels}, {"enc_conv1", 8}, {"enc_conv2", 8}, {"enc_conv3", 12}, {"enc_conv4", 8},
      {"enc_conv5a", 16}, {"enc_conv5b", 8}, {"dec_conv4a", 16 + 8}, {"dec_conv4b", 8}, {"dec_conv3a", 16 + 12},
      {"dec_conv3b", 8}, {"dec_conv2a", 8 + 8}, {"dec_conv2b", 16}, {"dec_conv1a", 8 + inputChannels},
      {"dec_conv1b", 16}, {"dec_conv0", 8}};
  Rng rng(seed, 0);
  std::map<std::string, TzaTensor> w;
  for (const auto& [name, o] : outs) {
    const int i = in.at(name);
    TzaTensor t{{o, i, 3, 3}, "oihw", {}};
    const float scale = 1.6f / std::sqrt(float(9 * i));
    for (size_t k = 0; k < t.size(); ++k) t.values.push_back(scale * (2.0f * rng.uniform() - 1.0f));
    w[name + ".weight"] = t;
    TzaTensor b{{o}, "x", {}};
    for (int k = 0; k < o; ++k) b.values.push_back(0.1f * (2.0f * rng.uniform() - 0.8f));
    w[name + ".bias"] = b;
  }
  return w;
}

/// A tensor of C x H x W, plainly indexed.
struct Plain {
  int c = 0, h = 0, w = 0;
  std::vector<double> v;
  Plain(int c_, int h_, int w_) : c(c_), h(h_), w(w_), v(size_t(c_) * size_t(h_) * size_t(w_), 0.0) {}
  double& at(int k, int y, int x) { return v[(size_t(k) * size_t(h) + size_t(y)) * size_t(w) + size_t(x)]; }
  double at(int k, int y, int x) const { return v[(size_t(k) * size_t(h) + size_t(y)) * size_t(w) + size_t(x)]; }
};

Plain conv(const Plain& in, const TzaTensor& w, const TzaTensor& b) {
  Plain out(w.dims[0], in.h, in.w);
  for (int o = 0; o < out.c; ++o)
    for (int y = 0; y < in.h; ++y)
      for (int x = 0; x < in.w; ++x) {
        double s = b.values[size_t(o)];
        for (int i = 0; i < in.c; ++i)
          for (int ky = 0; ky < 3; ++ky)
            for (int kx = 0; kx < 3; ++kx) {
              const int yy = y + ky - 1, xx = x + kx - 1;
              if (yy < 0 || xx < 0 || yy >= in.h || xx >= in.w) continue;
              s += in.at(i, yy, xx) * w.values[((size_t(o) * size_t(in.c) + size_t(i)) * 3 + size_t(ky)) * 3 + size_t(kx)];
            }
        out.at(o, y, x) = std::max(s, 0.0);
      }
  return out;
}
Plain pool(const Plain& in) {
  Plain out(in.c, in.h / 2, in.w / 2);
  for (int k = 0; k < in.c; ++k)
    for (int y = 0; y < out.h; ++y)
      for (int x = 0; x < out.w; ++x)
        out.at(k, y, x) = std::max(std::max(in.at(k, 2 * y, 2 * x), in.at(k, 2 * y, 2 * x + 1)),
                                   std::max(in.at(k, 2 * y + 1, 2 * x), in.at(k, 2 * y + 1, 2 * x + 1)));
  return out;
}
/// Nearest-neighbour upsampling of `a`, then `b`'s channels after its own.
Plain upConcat(const Plain& a, const Plain& b) {
  Plain out(a.c + b.c, b.h, b.w);
  for (int y = 0; y < b.h; ++y)
    for (int x = 0; x < b.w; ++x) {
      for (int k = 0; k < a.c; ++k) out.at(k, y, x) = a.at(k, y / 2, x / 2);
      for (int k = 0; k < b.c; ++k) out.at(a.c + k, y, x) = b.at(k, y, x);
    }
  return out;
}

/// The whole filter, loop by loop: OIDN's input processing, the U-Net at the padded size, the
/// output mapped back and cropped.
Image plainDenoise(const std::map<std::string, TzaTensor>& w, const Image& color, const Image* albedo,
                   const Image* normal) {
  const int C = 3 + (albedo ? 3 : 0) + (normal ? 3 : 0);
  const int H = (color.height + 15) / 16 * 16, W = (color.width + 15) / 16 * 16;
  const float scale = Denoiser::autoexposure(color);
  Plain input(C, H, W);
  for (int y = 0; y < color.height; ++y)
    for (int x = 0; x < color.width; ++x)
      for (int k = 0; k < 3; ++k) {
        input.at(k, y, x) = Denoiser::puForward(std::max(color.at(x, y)[k] * scale, 0.0f));
        if (albedo) input.at(3 + k, y, x) = std::clamp(albedo->at(x, y)[k], 0.0f, 1.0f);
        if (normal) input.at(6 + k, y, x) = std::clamp(normal->at(x, y)[k], -1.0f, 1.0f) * 0.5f + 0.5f;
      }
  const auto L = [&](const Plain& in, const std::string& n) { return conv(in, w.at(n + ".weight"), w.at(n + ".bias")); };
  const Plain p1 = pool(L(L(input, "enc_conv0"), "enc_conv1"));
  const Plain p2 = pool(L(p1, "enc_conv2"));
  const Plain p3 = pool(L(p2, "enc_conv3"));
  const Plain p4 = pool(L(p3, "enc_conv4"));
  Plain x = L(L(p4, "enc_conv5a"), "enc_conv5b");
  x = L(L(upConcat(x, p3), "dec_conv4a"), "dec_conv4b");
  x = L(L(upConcat(x, p2), "dec_conv3a"), "dec_conv3b");
  x = L(L(upConcat(x, p1), "dec_conv2a"), "dec_conv2b");
  x = L(L(L(upConcat(x, input), "dec_conv1a"), "dec_conv1b"), "dec_conv0");
  Image out(color.width, color.height);
  for (int y = 0; y < color.height; ++y)
    for (int xx = 0; xx < color.width; ++xx)
      for (int k = 0; k < 3; ++k) out.at(xx, y)[k] = Denoiser::puInverse(float(x.at(k, y, xx))) / scale;
  return out;
}

/// A random HDR image (a ramp with noise and a few bright pixels), albedo and unit normals.
struct Inputs {
  Image color, albedo, normal;
};
Inputs randomInputs(int w, int h, uint64_t seed) {
  Inputs in{Image(w, h), Image(w, h), Image(w, h)};
  Rng rng(seed, 0);
  for (size_t p = 0; p < in.color.pixels.size(); ++p) {
    const float ramp = 0.2f + float(p % size_t(w)) / float(w);
    in.color.pixels[p] = Vec3(ramp * rng.uniform(), ramp * rng.uniform(), ramp * rng.uniform() * 2.0f);
    if (p % 97 == 0) in.color.pixels[p] *= 40.0f;
    in.albedo.pixels[p] = Vec3(rng.uniform(), rng.uniform(), rng.uniform());
    in.normal.pixels[p] = glm::normalize(Vec3(rng.uniform() - 0.5f, rng.uniform() - 0.5f, rng.uniform() - 0.5f));
  }
  return in;
}

TEST(Denoiser, TheBlockedNetworkComputesThePlainUNet) {
  // 37 x 21: both sides padded to 48 x 32; one, two and three inputs.
  const Inputs in = randomInputs(37, 21, 5);
  for (int channels : {3, 6, 9}) {
    const auto weights = randomNetwork(channels, 17 + uint64_t(channels));
    const Image* albedo = channels >= 6 ? &in.albedo : nullptr;
    const Image* normal = channels == 9 ? &in.normal : nullptr;
    const Image plain = plainDenoise(weights, in.color, albedo, normal);
    Denoiser d(weights, channels);
    for (const std::string& kernel : Denoiser::kernels()) {
      d.setKernel(kernel);
      const Image fast = d.denoise(in.color, albedo, normal);
      double worst = 0.0, sum = 0.0;
      for (size_t p = 0; p < plain.pixels.size(); ++p)
        for (int k = 0; k < 3; ++k) {
          sum += plain.pixels[p][k];
          worst = std::max(worst, double(std::abs(fast.pixels[p][k] - plain.pixels[p][k])) /
                                      (1e-3 + std::abs(plain.pixels[p][k])));
        }
      // The sums differ only in rounding (float against double, FMA); the output is not trivial.
      EXPECT_LT(worst, 1e-3) << channels << " channels, kernel " << kernel;
      EXPECT_GT(sum, 0.01 * double(plain.pixels.size())) << channels << " channels";
    }
  }
}

TEST(Denoiser, TheSameImageAtAnyThreadCount) {
  const Inputs in = randomInputs(70, 45, 9);
  const Denoiser d(randomNetwork(9, 3), 9);
  Image images[2];
  for (int threads : {1, 2}) {
    ThreadLimit limit(threads);
    images[threads - 1] = d.denoise(in.color, &in.albedo, &in.normal);
  }
  EXPECT_TRUE(images[0].pixels == images[1].pixels);
}

TEST(Denoiser, TilesGiveTheWholeImagesValuesBitForBit) {
  // 600 x 400 in tiles of 64 (windows of 64 + 2 x 128): the same image as in one piece, since
  // each window starts on the pooling grid and is wider than the receptive field; tiles of 48
  // with an odd image size too.
  for (const auto& [w, h, tile] : {std::tuple{600, 400, 64}, std::tuple{517, 389, 48}}) {
    const Inputs in = randomInputs(w, h, 11);
    Denoiser d(randomNetwork(9, 4), 9);
    const Image whole = d.denoise(in.color, &in.albedo, &in.normal);
    d.setTiling(tile);
    DenoiseTimings t;
    const Image tiled = d.denoise(in.color, &in.albedo, &in.normal, &t);
    EXPECT_TRUE(whole.pixels == tiled.pixels) << w << "x" << h;
    EXPECT_GT(t.network, 0.0);
  }
  Denoiser d(randomNetwork(9, 4), 9);
  EXPECT_THROW(d.setTiling(40), SettingsError);
}

TEST(Denoiser, WrongWeightsAndInputsAreErrors) {
  auto weights = randomNetwork(9, 1);
  EXPECT_THROW(Denoiser(weights, 6), ImageError);  // enc_conv0 takes 9 channels
  EXPECT_THROW(Denoiser(weights, 4), SettingsError);
  auto missing = weights;
  missing.erase("dec_conv2a.bias");
  EXPECT_THROW(Denoiser(missing, 9), ImageError);
  auto flat = weights;
  flat["enc_conv1.weight"].dims = {8, 72, 1, 1};
  EXPECT_THROW(Denoiser(flat, 9), ImageError);
  const Denoiser d(weights, 9);
  const Inputs in = randomInputs(16, 16, 2);
  EXPECT_THROW(d.denoise(in.color, &in.albedo, nullptr), SettingsError);
  const Image small(8, 16);
  EXPECT_THROW(d.denoise(in.color, &in.albedo, &small), SettingsError);
  EXPECT_THROW(Denoiser::weightsFile(false, true), SettingsError);
  Denoiser k(weights, 9);
  EXPECT_THROW(k.setKernel("neon"), SettingsError);
  EXPECT_EQ(k.kernel(), Denoiser::kernels().front());
  EXPECT_EQ(Denoiser::weightsFile(true, true), "rt_hdr_alb_nrm.tza");
  // Non-finite colour counts as black (as OIDN sanitizes it): the output stays finite.
  Image nan = in.color;
  nan.pixels[3] = Vec3(std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(), -1.0f);
  for (const Vec3& p : d.denoise(nan, &in.albedo, &in.normal).pixels)
    EXPECT_TRUE(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z));
}

// ---- the published weights on renders (tools/fetch_models.sh)

/// The fetched weights for colour, albedo and normal, or nullptr (the test is skipped).
const Denoiser* fetchedDenoiser() {
  static const std::unique_ptr<Denoiser> d = []() -> std::unique_ptr<Denoiser> {
    const std::string path = test::sourceDir() + "/data/models/oidn/rt_hdr_alb_nrm.tza";
    if (!std::filesystem::exists(path)) return nullptr;
    return std::make_unique<Denoiser>(readTza(path), 9);
  }();
  return d.get();
}

/// A path-traced render of `scene` at 128 x 128 with its albedo and normal layers.
struct Render {
  Image color, albedo, normal;
};
Render pathRender(const Scene& scene, int spp, uint64_t seed) {
  const Hbvh accel(scene);
  RenderSettings s = scene.render;
  s.width = s.height = 128;
  s.spp = spp;
  s.seed = seed;
  s.method = "path";
  IntegratorContext ctx{scene, accel, s, nlohmann::json::object()};
  auto integrator = createIntegrator("path", ctx);
  integrator->prepare(nullptr);
  AovRequest request;
  request.accel = &accel;
  request.layers = {Aov::Albedo, Aov::Normal};
  RenderResult r = renderImage(scene, *integrator, s, nullptr, false, &request);
  Render out{r.image, Image(s.width, s.height), Image(s.width, s.height)};
  for (size_t p = 0; p < out.color.pixels.size(); ++p)
    for (int k = 0; k < 3; ++k) {
      out.albedo.pixels[p][k] = r.layers[0].values[3 * p + size_t(k)];
      out.normal.pixels[p][k] = r.layers[1].values[3 * p + size_t(k)];
    }
  return out;
}


struct DenoiseCase {
  const char* scene;
  double gain4, gain16;  ///< the least PSNR gain at 4 and 16 spp, dB
};

/// Denoised path at 4 and 16 spp against path at 256 spp (another seed): PSNR up by the
/// stated margin and every 4x4 cell within 8% (4 spp) and 4% (16 spp) of the reference.
/// Measured at 128x128 with a 512-spp reference: cornell-box 24.9 -> 37.6 dB (4 spp), 31.7 ->
/// 41.0 (16); two-rooms-door 21.6 -> 38.6, 26.3 -> 39.4; small-objects 27.2 -> 39.3, 33.6 ->
/// 42.4; worst cells 0.943 (4 spp), 1.023 (16 spp).
TEST(DenoiserWeights, DenoisedPathGainsPsnrAndKeepsEveryCellsEnergy) {
  const Denoiser* d = fetchedDenoiser();
  if (!d) GTEST_SKIP() << "run tools/fetch_models.sh to fetch the denoiser's weights";
  for (const DenoiseCase& c : {DenoiseCase{"cornell-box", 9.0, 6.0}, DenoiseCase{"failure/two-rooms-door", 12.0, 9.0},
                               DenoiseCase{"failure/small-objects", 8.0, 6.0}}) {
    const Scene scene = loadScene(test::sourceDir() + "/data/scenes/" + c.scene + ".json");
    const Image ref = pathRender(scene, 256, 7).color;
    for (int spp : {4, 16}) {
      const Render r = pathRender(scene, spp, 0);
      const Image den = d->denoise(r.color, &r.albedo, &r.normal);
      const double raw = compareImages(r.color, ref).psnrSrgb8, out = compareImages(den, ref).psnrSrgb8;
      EXPECT_GT(out - raw, spp == 4 ? c.gain4 : c.gain16) << c.scene << " at " << spp << " spp: " << raw << " -> " << out;
      EXPECT_LT(test::worstCellDeviation(den, ref), spp == 4 ? 0.08 : 0.04) << c.scene << " at " << spp << " spp";
    }
  }
}

/// The published network's tensors: 1024 x 1024 runs in one piece, 3840 x 2160 in tiles
/// (`voxcone denoise` measured: 1024 x 1024 at 1.31 GB peak RSS, 3840 x 2160 at 2.0 GB where in
/// one piece its tensors alone would take 8 GB).
TEST(DenoiserWeights, LargeImagesAreTiledUnderTheMemoryBudget) {
  const Denoiser* d = fetchedDenoiser();
  if (!d) GTEST_SKIP() << "run tools/fetch_models.sh to fetch the denoiser's weights";
  EXPECT_LE(d->memoryBytes(1024, 1024), Denoiser::kMaxMemory) << d->memoryBytes(1024, 1024);
  EXPECT_GT(d->memoryBytes(3840, 2160), Denoiser::kMaxMemory);
  EXPECT_LT(d->memoryBytes(256, 256), size_t(100) << 20);
}

/// A converged render (512 spp) denoised is no further from another converged render than it
/// was before: the network removes what noise is left and blurs nothing that is not noise.
/// Measured on cornell-box at 128x128: relMSE 0.00035 before, 0.00024 after.
TEST(DenoiserWeights, AConvergedImageStaysWithinItsNoise) {
  const Denoiser* d = fetchedDenoiser();
  if (!d) GTEST_SKIP() << "run tools/fetch_models.sh to fetch the denoiser's weights";
  const Scene scene = test::cornellBox();
  const Image ref = pathRender(scene, 512, 7).color;
  const Render r = pathRender(scene, 512, 8);
  const double before = compareImages(r.color, ref).relMse;
  const Image den = d->denoise(r.color, &r.albedo, &r.normal);
  EXPECT_LT(compareImages(den, ref).relMse, before);
  EXPECT_LT(test::worstCellDeviation(den, ref), 0.01);
}

}  // namespace
}  // namespace voxcone

/// \file test_metrics.cpp
/// Image metrics against hand-computed values, an independent SSIM and OpenImageIO's compare.

#include "voxcone/core/error.h"
#include "voxcone/image/image_io.h"
#include "voxcone/image/metrics.h"

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using namespace voxcone;

namespace {

/// Image whose every channel holds the linear value of a random 8-bit code in [lo, hi].
Image randomCodes(int w, int h, unsigned seed, int lo = 0, int hi = 255) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> code(lo, hi);
  Image im(w, h);
  for (auto& p : im.pixels)
    p = Vec3(srgbToLinear(code(rng) / 255.0f), srgbToLinear(code(rng) / 255.0f), srgbToLinear(code(rng) / 255.0f));
  return im;
}

/// Straightforward SSIM for the cross-check: full 2D window weights, two-pass moments around the
/// window means (compareImages uses separable filtering of raw moments).
double directSsim(const Image& a, const Image& b) {
  const int w = a.width, h = a.height;
  const int nx = std::min(11, w), ny = std::min(11, h);
  const auto luma = [](const Vec3& p) { return 0.2126 * toSrgb8(p.x) + 0.7152 * toSrgb8(p.y) + 0.0722 * toSrgb8(p.z); };
  std::vector<double> weight(static_cast<size_t>(nx * ny));
  double wsum = 0.0;
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const double dx = i - 0.5 * (nx - 1), dy = j - 0.5 * (ny - 1);
      wsum += weight[j * nx + i] = std::exp(-(dx * dx + dy * dy) / (2.0 * 1.5 * 1.5));
    }
  for (double& v : weight) v /= wsum;
  const double c1 = std::pow(0.01 * 255, 2), c2 = std::pow(0.03 * 255, 2);
  double total = 0.0;
  int count = 0;
  for (int y0 = 0; y0 + ny <= h; ++y0)
    for (int x0 = 0; x0 + nx <= w; ++x0) {
      double mx = 0, my = 0;
      for (int j = 0; j < ny; ++j)
        for (int i = 0; i < nx; ++i) {
          mx += weight[j * nx + i] * luma(a.at(x0 + i, y0 + j));
          my += weight[j * nx + i] * luma(b.at(x0 + i, y0 + j));
        }
      double vx = 0, vy = 0, cxy = 0;
      for (int j = 0; j < ny; ++j)
        for (int i = 0; i < nx; ++i) {
          const double da = luma(a.at(x0 + i, y0 + j)) - mx, db = luma(b.at(x0 + i, y0 + j)) - my;
          vx += weight[j * nx + i] * da * da;
          vy += weight[j * nx + i] * db * db;
          cxy += weight[j * nx + i] * da * db;
        }
      total += (2 * mx * my + c1) * (2 * cxy + c2) / ((mx * mx + my * my + c1) * (vx + vy + c2));
      ++count;
    }
  return total / count;
}

/// OpenImageIO buffer over a copy of the pixels, as float or as 8-bit sRGB codes.
OIIO::ImageBuf toImageBuf(const Image& im, bool srgb8) {
  const OIIO::ImageSpec spec(im.width, im.height, 3, srgb8 ? OIIO::TypeDesc::UINT8 : OIIO::TypeDesc::FLOAT);
  OIIO::ImageBuf buf(spec);
  if (srgb8) {
    std::vector<uint8_t> codes;
    for (const Vec3& p : im.pixels)
      for (int c = 0; c < 3; ++c) codes.push_back(static_cast<uint8_t>(toSrgb8(p[c])));
    buf.set_pixels(OIIO::ROI::All(), OIIO::TypeDesc::UINT8, codes.data());
  } else {
    buf.set_pixels(OIIO::ROI::All(), OIIO::TypeDesc::FLOAT, im.pixels.data());
  }
  return buf;
}

}  // namespace

TEST(MetricsCompare, HandComputed2x2) {
  // ref  = (1,1,1)          (0,0,0)                (0.5,0.5,0.5)  (0.5,0.5,0.5)
  // test = (1.25,1.25,1.25) (0.125,0.125,0.125)    (0.5,0.5,0.5)  (0.5,0.5,0.5)
  // (all values exact in binary). Squared differences: 0.0625 x3, 0.015625 x3, 0 x6.
  // MSE    = (3*0.0625 + 3*0.015625) / 12 = 0.234375 / 12 = 0.01953125
  // relMSE = (3*0.0625/(1+0.01) + 3*0.015625/(0+0.01)) / 12
  //        = (0.185643564356... + 4.6875) / 12 = 0.406095297029703
  // 8-bit: 1.25 and 1 both clamp to 255; 0.125 -> 255*(1.055*0.125^(1/2.4)-0.055) = 99.086 -> 99
  // vs 0; the 0.5s are equal. MSE8 = 3*99^2/12 = 2450.25; PSNR = 10 log10(65025/2450.25)
  // = 14.23869963 dB.
  Image ref(2, 2, Vec3(0.5f)), test(2, 2, Vec3(0.5f));
  ref.at(0, 0) = Vec3(1.0f);
  test.at(0, 0) = Vec3(1.25f);
  ref.at(1, 0) = Vec3(0.0f);
  test.at(1, 0) = Vec3(0.125f);
  const ImageMetrics m = compareImages(test, ref);
  EXPECT_DOUBLE_EQ(m.mse, 0.01953125);
  EXPECT_NEAR(m.relMse, 0.406095297029703, 1e-14);
  EXPECT_NEAR(m.psnrSrgb8, 14.23869963000773, 1e-9);
  EXPECT_GT(m.ssim, -1.0);
  EXPECT_LT(m.ssim, 1.0);
  EXPECT_NEAR(m.ssim, directSsim(test, ref), 1e-12);
  // Per-pixel errors 0.0625 / 1.01, 0.015625 / 0.01, 0, 0: the 99th percentile (rank 4 of 4) is
  // the largest, 1.5625.
  EXPECT_DOUBLE_EQ(m.relErrorP99, 1.5625);
  // Means: test (1.25 + 0.125 + 0.5 + 0.5) / 4 = 0.59375, reference (1 + 0 + 0.5 + 0.5) / 4 = 0.5.
  for (int c = 0; c < 3; ++c) {
    EXPECT_DOUBLE_EQ(m.meanTest[c], 0.59375);
    EXPECT_DOUBLE_EQ(m.meanReference[c], 0.5);
  }
  // relMSE is not symmetric (it divides by the reference).
  EXPECT_NE(compareImages(ref, test).relMse, m.relMse);
}

TEST(MetricsCompare, RelMseOfEstimatesHandComputed2x2) {
  // The images of HandComputed2x2. Means of the pairs: 1.125 and 0.0625 (the 0.5s are equal).
  // (0.25^2 / (1.125^2 + 0.01) x3 + 0.125^2 / (0.0625^2 + 0.01) x3) / 12
  //   = (3 x 0.0625 / 1.275625 + 3 x 0.015625 / 0.01390625) / 12
  //   = (0.146986771190... + 3.370786516853...) / 12 = 0.293147774003...
  Image a(2, 2, Vec3(0.5f)), b(2, 2, Vec3(0.5f));
  a.at(0, 0) = Vec3(1.0f);
  b.at(0, 0) = Vec3(1.25f);
  a.at(1, 0) = Vec3(0.0f);
  b.at(1, 0) = Vec3(0.125f);
  const double expected = (3.0 * 0.0625 / 1.275625 + 3.0 * 0.015625 / 0.01390625) / 12.0;
  EXPECT_NEAR(relMseOfEstimates(a, b), expected, 1e-14);
  EXPECT_DOUBLE_EQ(relMseOfEstimates(a, b), relMseOfEstimates(b, a));  // symmetric
  EXPECT_EQ(relMseOfEstimates(a, a), 0.0);
  EXPECT_THROW(relMseOfEstimates(a, Image(3, 2)), ImageError);
}

TEST(MetricsCompare, IdenticalImages) {
  const Image im = randomCodes(32, 24, 7);
  const ImageMetrics m = compareImages(im, im);
  EXPECT_EQ(m.relMse, 0.0);
  EXPECT_EQ(m.mse, 0.0);
  EXPECT_TRUE(std::isinf(m.psnrSrgb8) && m.psnrSrgb8 > 0.0);
  EXPECT_DOUBLE_EQ(m.ssim, 1.0);
  // Values that differ in linear float but quantise to the same 8-bit codes: PSNR still +inf.
  Image near = im;
  for (auto& p : near.pixels) p *= 1.0001f;
  const ImageMetrics n = compareImages(near, im);
  EXPECT_GT(n.mse, 0.0);
  EXPECT_EQ(n.psnrSrgb8, std::numeric_limits<double>::infinity());
}

TEST(MetricsCompare, PsnrOneCodeOffset) {
  // Every 8-bit code off by one: MSE8 = 1, PSNR = 10 log10(255^2) = 48.1308036 dB.
  const Image ref = randomCodes(20, 10, 3, 0, 254);
  Image test = ref;
  for (auto& p : test.pixels)
    for (int c = 0; c < 3; ++c) p[c] = srgbToLinear((toSrgb8(p[c]) + 1) / 255.0f);
  EXPECT_NEAR(compareImages(test, ref).psnrSrgb8, 48.1308036086791, 1e-9);
  EXPECT_NEAR(compareImages(ref, test).psnrSrgb8, 48.1308036086791, 1e-9);
}

TEST(MetricsCompare, RegionErrorsHandComputed) {
  // 5 x 3 in a 2 x 2 grid: cells are columns [0, 2) and [2, 5), rows [0, 1) and [1, 3). The
  // reference is 0.5 everywhere (code 188); the test is 1.0 (code 255, 67 codes off) in pixel
  // (4, 2) only: all the error is in the bottom-right cell, whose mean is (5 * 0.5 + 1) / 6.
  Image ref(5, 3), test(5, 3);
  for (Vec3& p : ref.pixels) p = Vec3(0.5f);
  test = ref;
  test.at(4, 2) = Vec3(1.0f);
  const std::vector<RegionError> cells = regionErrors(test, ref, 2);
  ASSERT_EQ(cells.size(), 4u);
  EXPECT_EQ(cells[1].x0, 2);
  EXPECT_EQ(cells[1].x1, 5);
  EXPECT_EQ(cells[2].y0, 1);
  EXPECT_EQ(cells[2].y1, 3);
  EXPECT_DOUBLE_EQ(cells[3].errorShare, 1.0);
  EXPECT_DOUBLE_EQ(cells[0].errorShare, 0.0);
  EXPECT_NEAR(cells[3].meanTest.x, (5 * 0.5 + 1.0) / 6.0, 1e-12);
  EXPECT_NEAR(cells[3].meanReference.y, 0.5, 1e-12);
  EXPECT_NEAR(cells[0].meanTest.z, 0.5, 1e-12);
  // Two wrong pixels in different cells, one twice the other's squared code error per channel.
  test.at(0, 0) = Vec3(srgbToLinear((188.0f + 67.0f / std::sqrt(2.0f)) / 255.0f));
  const std::vector<RegionError> two = regionErrors(test, ref, 2);
  EXPECT_NEAR(two[3].errorShare, 2.0 / 3.0, 0.02);
  EXPECT_NEAR(two[0].errorShare + two[3].errorShare, 1.0, 1e-12);
  EXPECT_THROW(regionErrors(test, ref, 4), ImageError);  // more cells than rows
  EXPECT_THROW(regionErrors(test, ref, 0), ImageError);
  EXPECT_THROW(regionErrors(test, Image(3, 3), 1), ImageError);
}

TEST(MetricsCompare, SsimOfConstantImages) {
  // Constant images have zero variance and covariance in every window, so SSIM reduces to the
  // luminance term (2 a b + C1) / (a^2 + b^2 + C1) with C1 = (0.01*255)^2 = 6.5025.
  // Grey codes 100 and 120 give luma 100 and 120: (24000 + 6.5025) / (24400 + 6.5025)
  // = 0.98361092499837.
  const Image a(16, 13, Vec3(srgbToLinear(100.0f / 255.0f)));
  const Image b(16, 13, Vec3(srgbToLinear(120.0f / 255.0f)));
  EXPECT_NEAR(compareImages(a, b).ssim, 0.9836109249983688, 1e-12);
}

TEST(MetricsCompare, SsimMatchesDirectImplementation) {
  // Larger than the window (several positions), exactly the window, and smaller than it.
  for (const auto& size : {std::pair<int, int>{23, 17}, {11, 11}, {11, 30}, {5, 4}, {1, 1}}) {
    const Image a = randomCodes(size.first, size.second, 11);
    Image b = randomCodes(size.first, size.second, 12);
    // Correlate b with a so that SSIM is far from 0.
    for (size_t i = 0; i < b.pixels.size(); ++i) b.pixels[i] = 0.7f * a.pixels[i] + 0.3f * b.pixels[i];
    const double expected = directSsim(a, b);
    EXPECT_NEAR(compareImages(a, b).ssim, expected, 1e-10) << size.first << "x" << size.second;
    EXPECT_NEAR(compareImages(b, a).ssim, expected, 1e-10) << size.first << "x" << size.second;
  }
}

TEST(MetricsCompare, CrossCheckWithOpenImageIO) {
  const Image ref = randomCodes(19, 8, 21);
  Image test = randomCodes(19, 8, 22);
  for (size_t i = 0; i < test.pixels.size(); ++i) test.pixels[i] = 0.5f * (test.pixels[i] + ref.pixels[i]);
  const ImageMetrics m = compareImages(test, ref);

  // MSE over linear floats: rms_error^2 of ImageBufAlgo::compare.
  const auto lin = OIIO::ImageBufAlgo::compare(toImageBuf(test, false), toImageBuf(ref, false), 1.0f, 1.0f);
  // (OpenImageIO sums in lower precision: agreement to 1e-6 relative.)
  EXPECT_NEAR(m.mse, lin.rms_error * lin.rms_error, 1e-6 * m.mse);
  // PSNR on 8-bit codes: OpenImageIO's PSNR of normalised values is 20 log10(1 / rms).
  const auto enc = OIIO::ImageBufAlgo::compare(toImageBuf(test, true), toImageBuf(ref, true), 1.0f, 1.0f);
  EXPECT_NEAR(m.psnrSrgb8, 20.0 * std::log10(1.0 / enc.rms_error), 1e-6);
}

TEST(MetricsCompare, SizeMismatchOrEmptyThrows) {
  EXPECT_THROW(compareImages(Image(4, 4), Image(4, 5)), ImageError);
  EXPECT_THROW(compareImages(Image(5, 4), Image(4, 4)), ImageError);
  EXPECT_THROW(compareImages(Image(), Image()), ImageError);
  EXPECT_THROW(falseColorError(Image(4, 4), Image(3, 4)), ImageError);
  // An 8-bit display image (clipped, quantized) against a float one: not comparable.
  Image png(4, 4);
  png.displayEncoded = true;
  EXPECT_THROW(compareImages(png, Image(4, 4)), ImageError);
  EXPECT_THROW(relMseOfEstimates(Image(4, 4), png), ImageError);
  EXPECT_NO_THROW(compareImages(png, png));
}

TEST(MetricsCompare, NonFiniteTestValuesGiveNonFiniteErrors) {
  Image test(3, 3, Vec3(0.5f));
  test.at(1, 1).y = std::numeric_limits<float>::quiet_NaN();
  const ImageMetrics m = compareImages(test, Image(3, 3, Vec3(0.5f)));
  EXPECT_TRUE(std::isnan(m.relMse));
  EXPECT_TRUE(std::isnan(m.mse));
  EXPECT_TRUE(m.toJson()["relmse"].is_null());
}

TEST(MetricsJson, KeysAndInfinity) {
  ImageMetrics m;
  m.relMse = 0.25;
  m.mse = 0.5;
  m.psnrSrgb8 = 31.5;
  m.ssim = 0.75;
  m.relErrorP99 = 2.0;
  m.meanTest = DVec3(0.5, 0.25, 0.125);
  m.meanReference = DVec3(1.0, 2.0, 4.0);
  EXPECT_EQ(m.toJson(), nlohmann::json::parse(R"({"relmse":0.25,"mse":0.5,"psnr_srgb8":31.5,"ssim":0.75,"relerr_p99":2.0,
      "mean":[0.5,0.25,0.125],"mean_reference":[1.0,2.0,4.0]})"));
  m.psnrSrgb8 = std::numeric_limits<double>::infinity();
  EXPECT_TRUE(m.toJson()["psnr_srgb8"].is_null());
  EXPECT_EQ(m.toJson().size(), 7u);
}

TEST(MetricsFalseColor, RampEndsAndScaling) {
  const Vec3 bottom(srgbToLinear(0.0f), srgbToLinear(0.0f), srgbToLinear(4.0f / 255.0f));
  const Vec3 top(srgbToLinear(252.0f / 255.0f), srgbToLinear(1.0f), srgbToLinear(164.0f / 255.0f));
  const auto near = [](const Vec3& a, const Vec3& b) { return glm::all(glm::lessThan(glm::abs(a - b), Vec3(1e-6f))); };

  // Identical images: every pixel at the bottom of the ramp.
  const Image ref(10, 10, Vec3(0.0f));
  for (const Vec3& p : falseColorError(ref, ref).pixels) EXPECT_TRUE(near(p, bottom));

  // Reference 0, test value v in every channel: error v^2 / 0.01. Pixel i gets v = i/100, so
  // errors are strictly increasing; the 99th percentile of 100 values is the 99th smallest.
  Image test(10, 10);
  for (int i = 0; i < 100; ++i) test.pixels[i] = Vec3(float(i) / 100.0f);
  const Image map = falseColorError(test, ref);
  EXPECT_TRUE(near(map.pixels[0], bottom));
  EXPECT_TRUE(near(map.pixels[98], top));
  EXPECT_TRUE(near(map.pixels[99], top));
  EXPECT_FALSE(near(map.pixels[97], top));
  // Perceptually ordered: luminance grows with the error.
  for (int i = 1; i < 99; ++i) EXPECT_GT(luminance(map.pixels[i]), luminance(map.pixels[i - 1])) << i;

  // Explicit maximum: pixel 50 (error 25) at the top, larger errors clamped.
  const Image fixed = falseColorError(test, ref, 25.0);
  EXPECT_TRUE(near(fixed.pixels[50], top));
  EXPECT_TRUE(near(fixed.pixels[80], top));
  EXPECT_FALSE(near(fixed.pixels[49], top));
}

TEST(MetricsCompare, PngRoundTripIsLosslessIn8Bit) {
  // A PNG written and read back has the same 8-bit codes: PSNR +inf, SSIM 1.
  const fs::path file = fs::temp_directory_path() / ("voxcone-metrics-" + std::to_string(::getpid()) + ".png");
  Image im = randomCodes(12, 12, 5);
  for (auto& p : im.pixels) p *= 1.01f;
  writePng(file.string(), im);
  // Compared as what it was written as: 8-bit display-encoded (a float image is refused).
  Image expected = im;
  expected.displayEncoded = true;
  const ImageMetrics m = compareImages(readImage(file.string()), expected);
  fs::remove(file);
  EXPECT_EQ(m.psnrSrgb8, std::numeric_limits<double>::infinity());
  EXPECT_DOUBLE_EQ(m.ssim, 1.0);
  EXPECT_LT(m.relMse, 1e-3);
}

#ifdef VOXCONE_CLI_PATH
TEST(MetricsCli, CompareExitCodesAndJson) {
  const std::string cli = VOXCONE_CLI_PATH;
  if (!fs::exists(cli)) GTEST_SKIP() << "no CLI at " << cli;
  const fs::path dir = fs::temp_directory_path() / ("voxcone-metrics-cli-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string ref = (dir / "ref.exr").string(), test = (dir / "test.exr").string();
  Image refIm(8, 8, Vec3(0.5f)), testIm(8, 8, Vec3(0.5f));
  testIm.at(3, 3) = Vec3(0.75f);
  writeExr(ref, refIm, nullptr);
  writeExr(test, testIm, nullptr);
  const auto run = [&](const std::string& args) {
    const int status = std::system((cli + " compare " + args + " > " + (dir / "out.txt").string() + " 2> " +
                                    (dir / "err.txt").string()).c_str());
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  };
  // relMSE = 3 * 0.0625/0.26 / 192 = 0.00375601; PSNR well above 30 dB.
  EXPECT_EQ(run(test + " " + ref), 0);
  EXPECT_EQ(run(test + " " + ref + " --threshold-relmse 0.01 --threshold-psnr 30"), 0);
  EXPECT_EQ(run(test + " " + ref + " --threshold-relmse 0.001"), 1);
  EXPECT_EQ(run(test + " " + ref + " --threshold-psnr 60"), 1);
  EXPECT_EQ(run(test + " " + (dir / "missing.exr").string()), 2);
  EXPECT_EQ(run(test + " " + ref + " --json --error-image " + (dir / "err.png").string()), 0);
  const nlohmann::json j = nlohmann::json::parse(std::ifstream((dir / "out.txt").string()));
  EXPECT_NEAR(j["relmse"].get<double>(), 3 * 0.0625 / 0.26 / 192.0, 1e-12);
  EXPECT_EQ(readImage((dir / "err.png").string()).width, 8);
  // One pixel differs: the 99th percentile scale puts it at the top of the ramp; a scale twice
  // its error puts it half way, as falseColorError with that maximum does.
  const double e = 0.0625 / 0.26;
  EXPECT_EQ(run(test + " " + ref + " --error-scale " + std::to_string(2.0 * e) + " --error-image " + (dir / "half.exr").string()), 0);
  const Image half = readImage((dir / "half.exr").string());
  EXPECT_NEAR(glm::length(half.at(3, 3) - falseColorError(testIm, refIm, 2.0 * e).at(3, 3)), 0.0f, 1e-6f);
  EXPECT_GT(glm::length(half.at(3, 3) - falseColorError(testIm, refIm).at(3, 3)), 0.05f);
  EXPECT_NE(run(test + " " + ref + " --error-scale 0 --error-image " + (dir / "bad.png").string()), 0);
  EXPECT_FALSE(fs::exists(dir / "bad.png"));
  fs::remove_all(dir);
}
#endif

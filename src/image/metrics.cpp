/// \file metrics.cpp
/// Image error metrics (relMSE, MSE, PSNR of 8-bit sRGB, SSIM) and the false-colour error map.
///
/// Every metric is a direct loop over the documented definition, accumulated in double. The
/// sums are exact-by-construction (integer codes for PSNR) or a single pass, so OpenImageIO's
/// ImageBufAlgo would only add conversions; the tests cross-check MSE and PSNR against
/// ImageBufAlgo::compare instead.

#include "voxcone/image/metrics.h"

#include "voxcone/core/error.h"
#include "voxcone/image/image_io.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

namespace voxcone {

namespace {

/// SSIM parameters of Wang et al. 2004, "Image Quality Assessment: From Error Visibility to
/// Structural Similarity", IEEE TIP 13(4), Sec. III-C: 11x11 circular-symmetric Gaussian window
/// with sigma 1.5 samples, K1 = 0.01, K2 = 0.03, dynamic range L = 255 (8-bit codes).
constexpr int kSsimWindow = 11;
constexpr double kSsimSigma = 1.5;
constexpr double kSsimC1 = (0.01 * 255.0) * (0.01 * 255.0);
constexpr double kSsimC2 = (0.03 * 255.0) * (0.03 * 255.0);

void checkSizes(const Image& test, const Image& reference) {
  const auto describe = [](const Image& im) { return std::to_string(im.width) + "x" + std::to_string(im.height); };
  if (test.width <= 0 || test.height <= 0 || test.pixels.size() != size_t(test.width) * size_t(test.height))
    throw ImageError("compare: test image is empty or inconsistent (" + describe(test) + ")");
  if (reference.width <= 0 || reference.height <= 0 ||
      reference.pixels.size() != size_t(reference.width) * size_t(reference.height))
    throw ImageError("compare: reference image is empty or inconsistent (" + describe(reference) + ")");
  if (test.width != reference.width || test.height != reference.height)
    throw ImageError("compare: size mismatch: test " + describe(test) + ", reference " + describe(reference));
  if (test.displayEncoded != reference.displayEncoded)
    throw ImageError("compare: one image is 8-bit display-encoded (PNG, JPEG), the other float: compare like with like");
}

/// Normalised 1D Gaussian of `taps` samples centred on the middle of the window.
std::vector<double> gaussianTaps(int taps) {
  std::vector<double> w(static_cast<size_t>(taps));
  const double centre = 0.5 * (taps - 1);
  double sum = 0.0;
  for (int i = 0; i < taps; ++i) {
    w[i] = std::exp(-sqr(i - centre) / (2.0 * kSsimSigma * kSsimSigma));
    sum += w[i];
  }
  for (double& v : w) v /= sum;
  return w;
}

/// Rec. 709 luma of the 8-bit sRGB codes of each pixel (weights applied to code values, not to
/// linear values, as the usual "SSIM on the Y of the displayed image"; not rounded).
std::vector<double> srgb8Luma(const Image& image) {
  std::vector<double> y(image.pixels.size());
  for (size_t i = 0; i < image.pixels.size(); ++i) {
    const Vec3& p = image.pixels[i];
    y[i] = 0.2126 * toSrgb8(p.x) + 0.7152 * toSrgb8(p.y) + 0.0722 * toSrgb8(p.z);
  }
  return y;
}

/// Mean SSIM over every window position lying entirely inside the image ("valid" filtering, as
/// filter2(..., 'valid') in Wang's reference ssim_index.m). Images narrower or shorter than 11
/// pixels use a window of min(11, size) taps on that axis (same sigma, renormalised), giving a
/// single position on that axis. Wang's later automatic downsampling is not applied.
double meanSsim(const std::vector<double>& x, const std::vector<double>& y, int width, int height) {
  const int wx = std::min(kSsimWindow, width);
  const int wy = std::min(kSsimWindow, height);
  const std::vector<double> gx = gaussianTaps(wx);
  const std::vector<double> gy = gaussianTaps(wy);
  const int outW = width - wx + 1;
  const int outH = height - wy + 1;

  // Separable filtering of the five moment images x, y, x^2, y^2, xy: horizontal pass first.
  constexpr int kMoments = 5;
  std::vector<std::array<double, kMoments>> rows(static_cast<size_t>(outW) * height);
  for (int j = 0; j < height; ++j) {
    for (int i = 0; i < outW; ++i) {
      std::array<double, kMoments> acc{};
      for (int k = 0; k < wx; ++k) {
        const size_t idx = static_cast<size_t>(j) * width + i + k;
        const double a = x[idx], b = y[idx], w = gx[k];
        acc[0] += w * a;
        acc[1] += w * b;
        acc[2] += w * a * a;
        acc[3] += w * b * b;
        acc[4] += w * a * b;
      }
      rows[static_cast<size_t>(j) * outW + i] = acc;
    }
  }

  // Vertical pass and the SSIM index of each window (Wang et al. 2004, Eq. 13).
  double sum = 0.0;
  for (int j = 0; j < outH; ++j) {
    for (int i = 0; i < outW; ++i) {
      std::array<double, kMoments> m{};
      for (int k = 0; k < wy; ++k) {
        const auto& r = rows[static_cast<size_t>(j + k) * outW + i];
        for (int c = 0; c < kMoments; ++c) m[c] += gy[k] * r[c];
      }
      const double muX = m[0], muY = m[1];
      const double varX = m[2] - muX * muX;
      const double varY = m[3] - muY * muY;
      const double covXY = m[4] - muX * muY;
      sum += ((2.0 * muX * muY + kSsimC1) * (2.0 * covXY + kSsimC2)) /
             ((muX * muX + muY * muY + kSsimC1) * (varX + varY + kSsimC2));
    }
  }
  return sum / (double(outW) * double(outH));
}

/// Per-pixel relative squared error: mean over channels of (t-r)^2 / (r^2 + eps).
double pixelRelError(const Vec3& t, const Vec3& r) {
  double e = 0.0;
  for (int c = 0; c < 3; ++c) e += sqr(double(t[c]) - double(r[c])) / (sqr(double(r[c])) + kRelMseEpsilon);
  return e / 3.0;
}

/// 99th percentile (nearest rank) of the finite values of `err`; 0 when there are none.
double percentile99(const std::vector<double>& err) {
  std::vector<double> finite;
  finite.reserve(err.size());
  for (double e : err)
    if (std::isfinite(e)) finite.push_back(e);
  if (finite.empty()) return 0.0;
  const size_t rank = static_cast<size_t>(std::ceil(0.99 * double(finite.size())));
  const size_t k = std::min(finite.size() - 1, rank > 0 ? rank - 1 : 0);
  std::nth_element(finite.begin(), finite.begin() + static_cast<std::ptrdiff_t>(k), finite.end());
  const double p = finite[k];
  return p > 0.0 ? p : *std::max_element(finite.begin(), finite.end());
}

/// Matplotlib's "inferno" ramp (van der Walt and Smith 2015) sampled at 10 evenly spaced points,
/// as sRGB-encoded 8-bit codes: perceptually ordered, monotonic in lightness.
constexpr std::array<std::array<uint8_t, 3>, 10> kInferno = {{{0x00, 0x00, 0x04},
                                                              {0x1B, 0x0C, 0x42},
                                                              {0x4B, 0x0C, 0x6B},
                                                              {0x78, 0x1C, 0x6D},
                                                              {0xA5, 0x2C, 0x60},
                                                              {0xCF, 0x44, 0x46},
                                                              {0xED, 0x69, 0x25},
                                                              {0xFB, 0x9A, 0x06},
                                                              {0xF7, 0xD0, 0x3C},
                                                              {0xFC, 0xFF, 0xA4}}};

/// Linear RGB colour of `t` in [0,1] on the ramp: interpolated in sRGB-encoded space (as
/// matplotlib does), then decoded so that writing the image as PNG shows the ramp's colours.
Vec3 rampColor(double t) {
  t = std::isfinite(t) ? std::clamp(t, 0.0, 1.0) : 1.0;
  const double pos = t * double(kInferno.size() - 1);
  const size_t i0 = std::min(static_cast<size_t>(pos), kInferno.size() - 2);
  const double f = pos - double(i0);
  Vec3 out;
  for (int c = 0; c < 3; ++c) {
    const double enc = ((1.0 - f) * kInferno[i0][c] + f * kInferno[i0 + 1][c]) / 255.0;
    out[c] = srgbToLinear(static_cast<float>(enc));
  }
  return out;
}

}  // namespace

nlohmann::json ImageMetrics::toJson() const {
  // JSON has no infinity: identical 8-bit images (PSNR = +inf) give "psnr_srgb8": null, and so
  // does any non-finite value.
  const auto number = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  return nlohmann::json{{"relmse", number(relMse)}, {"mse", number(mse)}, {"psnr_srgb8", number(psnrSrgb8)},
                        {"ssim", number(ssim)},
                        {"relerr_p99", number(relErrorP99)},
                        {"mean", {number(meanTest.x), number(meanTest.y), number(meanTest.z)}},
                        {"mean_reference", {number(meanReference.x), number(meanReference.y), number(meanReference.z)}}};
}

double relMseOfEstimates(const Image& a, const Image& b) {
  checkSizes(a, b);
  double sum = 0.0;
  for (size_t i = 0; i < a.pixels.size(); ++i)
    for (int c = 0; c < 3; ++c) {
      const double x = a.pixels[i][c], y = b.pixels[i][c], m = 0.5 * (x + y);
      sum += (x - y) * (x - y) / (m * m + kRelMseEpsilon);
    }
  return sum / (3.0 * double(a.pixels.size()));
}

ImageMetrics compareImages(const Image& test, const Image& reference) {
  checkSizes(test, reference);
  ImageMetrics m;
  const size_t n = test.pixels.size();

  // relMSE and MSE over linear values; sum of squared 8-bit code differences for PSNR.
  double relSum = 0.0;
  std::vector<double> pixelErr(n);
  double sqSum = 0.0;
  uint64_t sq8Sum = 0;
  for (size_t i = 0; i < n; ++i) {
    const Vec3& t = test.pixels[i];
    const Vec3& r = reference.pixels[i];
    pixelErr[i] = pixelRelError(t, r);
    for (int c = 0; c < 3; ++c) {
      const double d = double(t[c]) - double(r[c]);
      m.meanTest[c] += double(t[c]);
      m.meanReference[c] += double(r[c]);
      sqSum += d * d;
      // eps keeps dark reference pixels from dominating (Rousselle et al. 2011).
      relSum += d * d / (sqr(double(r[c])) + kRelMseEpsilon);
      const int64_t d8 = toSrgb8(t[c]) - toSrgb8(r[c]);
      sq8Sum += static_cast<uint64_t>(d8 * d8);
    }
  }
  const double count = 3.0 * double(n);
  m.relMse = relSum / count;
  m.mse = sqSum / count;
  m.relErrorP99 = percentile99(pixelErr);
  m.meanTest /= double(n);
  m.meanReference /= double(n);
  const double mse8 = double(sq8Sum) / count;
  m.psnrSrgb8 = sq8Sum == 0 ? std::numeric_limits<double>::infinity() : 10.0 * std::log10(255.0 * 255.0 / mse8);

  m.ssim = meanSsim(srgb8Luma(test), srgb8Luma(reference), test.width, test.height);
  return m;
}

std::vector<RegionError> regionErrors(const Image& test, const Image& reference, int n) {
  checkSizes(test, reference);
  if (n < 1 || n > std::min(test.width, test.height))
    throw ImageError("compare: regions must be in [1, " + std::to_string(std::min(test.width, test.height)) +
                     "], got " + std::to_string(n));
  std::vector<RegionError> cells;
  std::vector<uint64_t> sq8(size_t(n) * size_t(n), 0);
  uint64_t total = 0;
  for (int cy = 0; cy < n; ++cy)
    for (int cx = 0; cx < n; ++cx) {
      RegionError c;
      c.x0 = int(int64_t(cx) * test.width / n);
      c.x1 = int(int64_t(cx + 1) * test.width / n);
      c.y0 = int(int64_t(cy) * test.height / n);
      c.y1 = int(int64_t(cy + 1) * test.height / n);
      uint64_t& e = sq8[size_t(cy) * size_t(n) + size_t(cx)];
      for (int y = c.y0; y < c.y1; ++y)
        for (int x = c.x0; x < c.x1; ++x) {
          const size_t i = size_t(y) * size_t(test.width) + size_t(x);
          for (int ch = 0; ch < 3; ++ch) {
            c.meanTest[ch] += double(test.pixels[i][ch]);
            c.meanReference[ch] += double(reference.pixels[i][ch]);
            const int64_t d8 = toSrgb8(test.pixels[i][ch]) - toSrgb8(reference.pixels[i][ch]);
            e += uint64_t(d8 * d8);
          }
        }
      const double pixels = double(c.x1 - c.x0) * double(c.y1 - c.y0);
      c.meanTest /= pixels;
      c.meanReference /= pixels;
      total += e;
      cells.push_back(c);
    }
  for (size_t i = 0; i < cells.size(); ++i) cells[i].errorShare = total > 0 ? double(sq8[i]) / double(total) : 0.0;
  return cells;
}

Image falseColorError(const Image& test, const Image& reference, double maxError) {
  checkSizes(test, reference);
  const size_t n = test.pixels.size();
  std::vector<double> err(n);
  for (size_t i = 0; i < n; ++i) err[i] = pixelRelError(test.pixels[i], reference.pixels[i]);

  // Scale: the given maximum, else the 99th percentile (nearest rank) of the finite errors, so
  // that a few fireflies do not flatten the rest of the map.
  double scale = maxError;
  if (!(scale > 0.0) || !std::isfinite(scale)) {
    scale = percentile99(err);
    // Identical images: everything maps to the bottom of the ramp.
    if (!(scale > 0.0)) scale = 1.0;
  }

  // Non-finite errors (NaN or inf in either image) map to the top of the ramp.
  Image out(test.width, test.height);
  for (size_t i = 0; i < n; ++i) out.pixels[i] = rampColor(std::isfinite(err[i]) ? err[i] / scale : 1.0);
  return out;
}

}  // namespace voxcone

#pragma once
/// \file metrics.h
/// Image error metrics against a reference.

#include "voxcone/image/image.h"

#include <nlohmann/json_fwd.hpp>

#include <vector>

namespace voxcone {

/// Errors of a test image against a reference of the same size.
struct ImageMetrics {
  /// Relative MSE: mean over pixels and channels of (t - r)^2 / (r^2 + eps), eps = 1e-2
  /// (the HDR metric of Rousselle et al. 2011 and most denoising studies).
  double relMse = 0.0;
  /// Mean squared error of linear values, over pixels and channels.
  double mse = 0.0;
  /// PSNR in dB of 8-bit sRGB values (clamped, sRGB OETF, rounded): 10 log10(255^2 / MSE8);
  /// +infinity for identical 8-bit images.
  double psnrSrgb8 = 0.0;
  /// Mean SSIM (Wang et al. 2004: 11x11 Gaussian window, sigma 1.5, K1 0.01, K2 0.03, L 255) over
  /// every window position inside the image, on the Rec. 709 luma of the 8-bit sRGB codes
  /// (weights applied to code values). Images under 11 pixels on an axis use min(11, size) taps.
  double ssim = 0.0;
  /// 99th percentile (nearest rank) of the per-pixel relative squared error (mean over channels
  /// of (t - r)^2 / (r^2 + eps)): the top of falseColorError's default scale.
  double relErrorP99 = 0.0;
  /// Mean of the test and of the reference image, linear, per channel (their ratio is the
  /// bias of a method whose noise averages out).
  DVec3 meanTest{0.0}, meanReference{0.0};
  nlohmann::json toJson() const;
};

/// epsilon of relMse.
constexpr double kRelMseEpsilon = 1e-2;

/// Compare; throws ImageError if the sizes differ, either is empty, or one is display-encoded
/// (Image::displayEncoded) and the other not.
ImageMetrics compareImages(const Image& test, const Image& reference);

/// relMSE of two estimates of the same image against their mean: mean over pixels and channels
/// of (a - b)^2 / (((a + b) / 2)^2 + eps). Symmetric, unlike compareImages' relMSE against a
/// reference: a pixel near zero in one noisy estimate (a light's edge missed by every sample)
/// does not count thousands of times over. For two independent estimates it is about twice the
/// relMSE of one against the truth. Throws ImageError if the sizes differ or either is empty.
double relMseOfEstimates(const Image& a, const Image& b);

/// One cell of regionErrors: a rectangle of the image.
struct RegionError {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;  ///< pixels [x0, x1) x [y0, y1)
  DVec3 meanTest{0.0}, meanReference{0.0};
  /// The cell's share of the whole image's 8-bit sRGB squared error (the cells sum to 1; 0 for
  /// identical images).
  double errorShare = 0.0;
};

/// The image cut into an n x n grid of cells (row-major, top row first; cells differ by at most
/// one pixel in size): each cell's means and share of the sRGB8 error, to see where a method's
/// error sits (n in [1, min(width, height)]). Throws ImageError as compareImages.
std::vector<RegionError> regionErrors(const Image& test, const Image& reference, int n);

/// False-colour map of the per-pixel relative squared error (mean over channels of
/// (t-r)^2/(r^2+eps)) on a perceptually ordered colour ramp, scaled so that `maxError` maps to
/// the top of the ramp (maxError <= 0: the 99th percentile of the image).
Image falseColorError(const Image& test, const Image& reference, double maxError = 0.0);

}  // namespace voxcone

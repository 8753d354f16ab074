/// \file cmd_compare.cpp
/// `voxcone compare TEST REF`: image metrics of a test image against a reference, with optional
/// pass/fail thresholds (exit code 1) for regression scripts.

#include "cli_util.h"
#include "commands.h"

#include "voxcone/core/error.h"
#include "voxcone/image/image_io.h"
#include "voxcone/image/metrics.h"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <string>

namespace voxcone {
namespace {

/// Values of the compare subcommand's arguments (owned by the callback).
struct CompareArgs {
  std::string testPath;
  std::string refPath;
  double thresholdRelMse = 0.0;
  double thresholdPsnrDb = 0.0;
  std::string errorImagePath;
  double errorScale = 0.0;
  bool json = false;
  int regions = 0;
  CLI::Option* thresholdRelMseOpt = nullptr;
  CLI::Option* thresholdPsnrOpt = nullptr;
};

/// printf-style formatting of one number.
std::string format(const char* fmt, double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), fmt, v);
  return buf;
}

/// Lower-case extension of `path`, dot included.
std::string lowerExtension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

void runCompare(const CompareArgs& args) {
  // Reject an unwritable error-image format before reading (possibly large) images.
  if (!args.errorImagePath.empty()) {
    const std::string ext = lowerExtension(args.errorImagePath);
    if (ext != ".png" && ext != ".exr")
      throw ImageError(args.errorImagePath + ": unsupported error-image extension '" + ext + "' (use .png or .exr)");
  }
  const Image test = readImage(args.testPath);
  const Image ref = readImage(args.refPath);
  // The metrics' checks (sizes; an 8-bit display image against a float one, which measured the
  // PNG's clipping: relMSE 0.55 with PSNR inf) name the two files here.
  ImageMetrics m;
  try {
    m = compareImages(test, ref);
  } catch (const ImageError& e) {
    throw ImageError(args.testPath + " against " + args.refPath + ": " + e.what());
  }

  if (!args.errorImagePath.empty()) {
    const std::string scale = args.errorScale > 0.0 ? "scale " + format("%.6g", args.errorScale) : "99th percentile scale";
    const nlohmann::json meta = {{"error_map", "per-pixel relative squared error, inferno ramp, " + scale},
                                 {"test", args.testPath},
                                 {"reference", args.refPath}};
    writeImage(args.errorImagePath, falseColorError(test, ref, args.errorScale), meta);
  }

  std::vector<RegionError> cells;
  if (args.regions > 0) cells = regionErrors(test, ref, args.regions);
  const auto lum = [](const DVec3& v) { return 0.2126 * v.x + 0.7152 * v.y + 0.0722 * v.z; };
  if (args.json) {
    nlohmann::json j = m.toJson();
    for (const RegionError& c : cells)
      j["regions"].push_back({{"x0", c.x0}, {"y0", c.y0}, {"x1", c.x1}, {"y1", c.y1},
                              {"mean_test", {c.meanTest.x, c.meanTest.y, c.meanTest.z}},
                              {"mean_reference", {c.meanReference.x, c.meanReference.y, c.meanReference.z}},
                              {"error_share", c.errorShare}});
    std::cout << j.dump() << std::endl;
  } else {
    std::cout << "relMSE        " << format("%.6g", m.relMse) << "\n"
              << "MSE           " << format("%.6g", m.mse) << "\n"
              << "PSNR (sRGB8)  " << (std::isinf(m.psnrSrgb8) ? std::string("inf") : format("%.4f", m.psnrSrgb8))
              << " dB\n"
              << "SSIM          " << format("%.6f", m.ssim) << std::endl;
    if (!cells.empty()) {
      // Per cell: the luminance ratio test / reference (the bias where the noise averages out)
      // and the cell's share of the image's sRGB8 squared error, rows top to bottom.
      std::cout << "regions (" << args.regions << "x" << args.regions
                << "): luminance test/reference, share of the sRGB8 error\n";
      for (int cy = 0; cy < args.regions; ++cy) {
        std::string row;
        for (int cx = 0; cx < args.regions; ++cx) {
          const RegionError& c = cells[size_t(cy) * size_t(args.regions) + size_t(cx)];
          const double r = lum(c.meanReference);
          row += (r > 0.0 ? format("%6.3f", lum(c.meanTest) / r) : std::string("     -")) +
                 format(" %4.1f%%  ", 100.0 * c.errorShare);
        }
        std::cout << row << "\n";
      }
      std::cout << std::flush;
    }
  }

  // Thresholds: written as !(value within bound) so that a NaN metric fails.
  std::string failures;
  if (args.thresholdRelMseOpt->count() > 0 && !(m.relMse <= args.thresholdRelMse))
    failures += "relMSE " + format("%.6g", m.relMse) + " exceeds --threshold-relmse " +
                format("%.6g", args.thresholdRelMse);
  if (args.thresholdPsnrOpt->count() > 0 && !(m.psnrSrgb8 >= args.thresholdPsnrDb)) {
    if (!failures.empty()) failures += "; ";
    failures += "PSNR " + format("%.4f", m.psnrSrgb8) + " dB is below --threshold-psnr " +
                format("%.4f", args.thresholdPsnrDb) + " dB";
  }
  if (!failures.empty()) {
    std::cerr << "voxcone compare: FAIL: " << failures << std::endl;
    throw CLI::RuntimeError(1);
  }
}

}  // namespace

void addCompareCommand(CLI::App& app) {
  auto args = std::make_shared<CompareArgs>();
  CLI::App* sub = app.add_subcommand(
      "compare", "Compare a test image with a reference: relMSE, MSE, PSNR (8-bit sRGB), SSIM");
  sub->add_option("TEST", args->testPath, "Test image (OpenEXR, PNG or JPEG)")
      ->required()
      ->type_name("");
  sub->add_option("REF", args->refPath, "Reference image of the same size")->required()->type_name("");
  args->thresholdRelMseOpt =
      sub->add_option("--threshold-relmse", args->thresholdRelMse, "Fail (exit 1) when relMSE is above X")
          ->type_name("X")
      ->default_str("off");
  args->thresholdPsnrOpt =
      sub->add_option("--threshold-psnr", args->thresholdPsnrDb, "Fail (exit 1) when PSNR (8-bit sRGB) is below DB")
          ->type_name("DB")
      ->default_str("off");
  sub->add_option("--error-image", args->errorImagePath,
                  "Write a false-colour map of the relative squared error (.png or .exr)")
      ->type_name("PATH");
  sub->add_option("--error-scale", args->errorScale,
                  "Relative squared error at the top of the error image's ramp; "
                  "give two images the same scale to compare them")
      ->check(positiveNumber())
      ->type_name("X")
      ->default_str("the error's 99th percentile");
  sub->add_option("--regions", args->regions,
                  "Also print an N x N grid of cells: each cell's luminance ratio test/reference and its share of "
                  "the sRGB8 squared error")
      ->check(CLI::Range(1, 64))
      ->type_name("N")
      ->default_str("off");
  sub->add_flag("--json", args->json, "Print the metrics as one JSON object instead of the table");
  sub->callback([args]() { runCompare(*args); });
}

}  // namespace voxcone

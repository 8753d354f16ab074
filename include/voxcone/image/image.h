#pragma once
/// \file image.h
/// A linear RGB float image (the film's output and the input of metrics).

#include "voxcone/core/math.h"

#include <string>
#include <vector>

namespace voxcone {

/// Row-major linear RGB image, row 0 at the top.
struct Image {
  int width = 0;
  int height = 0;
  std::vector<Vec3> pixels;
  /// Read from an integer, display-encoded file (PNG, JPEG: decoded to linear, but clipped to
  /// [0, 1] and quantized when it was written): not comparable with a float HDR image.
  bool displayEncoded = false;

  Image() = default;
  Image(int w, int h, const Vec3& fill = Vec3(0.0f))
      : width(w), height(h), pixels(static_cast<size_t>(w) * static_cast<size_t>(h), fill) {}
  Vec3& at(int x, int y) { return pixels[static_cast<size_t>(y) * width + x]; }
  const Vec3& at(int x, int y) const { return pixels[static_cast<size_t>(y) * width + x]; }
  /// Mean over all pixels and channels.
  double mean() const {
    double s = 0.0;
    for (const Vec3& p : pixels) s += double(p.x) + double(p.y) + double(p.z);
    return pixels.empty() ? 0.0 : s / (3.0 * double(pixels.size()));
  }
};

/// Channels written beside an image's RGB (an AOV such as albedo or depth): EXR channel names
/// ("Albedo.R", "Z"; the part before the dot is the layer) and width * height * channels.size()
/// values, pixel by pixel, row 0 at the top.
struct ImageLayer {
  std::string name;                   ///< what asked for it (--aov albedo)
  std::vector<std::string> channels;
  std::vector<float> values;
};

}  // namespace voxcone

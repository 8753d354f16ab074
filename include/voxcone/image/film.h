#pragma once
/// \file film.h
/// A render's film: per-pixel sums of its samples, the beauty's and its layers' (AOVs), in
/// double so that a mean does not depend on the float rounding of a long sum, and the image and
/// layers it hands to image I/O (each pixel's mean over the samples taken).

#include "voxcone/core/math.h"
#include "voxcone/image/image.h"

#include <cstddef>
#include <string>
#include <vector>

namespace voxcone {

/// One layer a Film sums beside the beauty: its name and its EXR channel names (ImageLayer).
struct FilmLayer {
  std::string name;
  std::vector<std::string> channels;
};

/// Per-pixel sums of a width x height render, row-major, row 0 at the top: the beauty's RGB and
/// every layer's channels. Pixels are independent: threads may add to different pixels at once.
/// A render in passes keeps the sums of its last complete pass (keepComplete) to fall back to
/// when it is interrupted (restoreComplete).
class Film {
public:
  /// An empty film (every sum 0) of `width` x `height` pixels, > 0, with `layers` beside the beauty.
  Film(int width, int height, std::vector<FilmLayer> layers = {});

  int width() const { return m_width; }
  int height() const { return m_height; }
  /// The beauty's sum at `pixel` (y * width + x).
  DVec3& beauty(size_t pixel) { return m_beauty[pixel]; }
  /// Whether there are layers beside the beauty.
  bool hasLayers() const { return m_channels > 0; }
  /// The sums of layer `layer`'s channels at `pixel`, in channel order.
  double* layerSums(size_t pixel, size_t layer) { return &m_layerSums[pixel * m_channels + m_offsets[layer]]; }

  /// Keep a copy of every sum as it is now (a pass just completed).
  void keepComplete();
  /// Go back to the sums keepComplete kept.
  void restoreComplete();

  /// The beauty: each pixel's sum over `samples` (> 0).
  Image image(int samples) const;
  /// The layers, in the order given: each sum over `samples` (> 0), as float.
  std::vector<ImageLayer> layers(int samples) const;

private:
  int m_width = 0, m_height = 0;
  std::vector<FilmLayer> m_layers;
  std::vector<size_t> m_offsets;  ///< each layer's first channel among a pixel's
  size_t m_channels = 0;          ///< the layers' channels per pixel
  std::vector<DVec3> m_beauty, m_beautyComplete;
  std::vector<double> m_layerSums, m_layerSumsComplete;  ///< pixel-major, m_channels per pixel
};

}  // namespace voxcone

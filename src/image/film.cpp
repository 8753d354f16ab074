// A render's per-pixel sums and their means (film.h).

#include "voxcone/image/film.h"

#include <utility>

namespace voxcone {

Film::Film(int width, int height, std::vector<FilmLayer> layers)
    : m_width(width), m_height(height), m_layers(std::move(layers)) {
  for (const FilmLayer& l : m_layers) {
    m_offsets.push_back(m_channels);
    m_channels += l.channels.size();
  }
  const size_t pixels = size_t(width) * size_t(height);
  m_beauty.assign(pixels, DVec3(0.0));
  m_layerSums.assign(pixels * m_channels, 0.0);
}

void Film::keepComplete() {
  m_beautyComplete = m_beauty;
  m_layerSumsComplete = m_layerSums;
}

void Film::restoreComplete() {
  m_beauty.swap(m_beautyComplete);
  m_layerSums.swap(m_layerSumsComplete);
}

Image Film::image(int samples) const {
  Image out(m_width, m_height);
  for (size_t p = 0; p < m_beauty.size(); ++p) out.pixels[p] = Vec3(m_beauty[p] / double(samples));
  return out;
}

std::vector<ImageLayer> Film::layers(int samples) const {
  std::vector<ImageLayer> out;
  if (!hasLayers()) return out;
  const size_t pixels = m_beauty.size();
  for (size_t i = 0; i < m_layers.size(); ++i) {
    ImageLayer l{m_layers[i].name, m_layers[i].channels, {}};
    const size_t nc = l.channels.size();
    l.values.resize(pixels * nc);
    for (size_t p = 0; p < pixels; ++p)
      for (size_t c = 0; c < nc; ++c) l.values[p * nc + c] = float(m_layerSums[p * m_channels + m_offsets[i] + c] / double(samples));
    out.push_back(std::move(l));
  }
  return out;
}

}  // namespace voxcone

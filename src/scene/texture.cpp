#include "voxcone/scene/texture.h"

#include "voxcone/core/error.h"
#include "voxcone/image/image_io.h"

#include <cmath>

namespace voxcone {

Texture::Texture(int width, int height, std::vector<Vec3> texels)
    : m_width(width), m_height(height), m_texels(std::move(texels)) {
  if (width < 1 || height < 1 || m_texels.size() != size_t(width) * size_t(height))
    throw Error("texture: " + std::to_string(width) + " x " + std::to_string(height) + " with " +
                std::to_string(m_texels.size()) + " texels");
  DVec3 sum(0.0);
  for (const Vec3& t : m_texels) {
    if (!isFinite(t) || t.x < 0.0f || t.y < 0.0f || t.z < 0.0f)
      throw Error("texture: a texel is negative or not finite");
    sum += DVec3(t);
  }
  m_mean = Vec3(sum / double(m_texels.size()));
}

Vec3 Texture::lookup(const Vec2& uv) const {
  // Continuous texel coordinates with texel centres at integers + 0.5; y from the top row.
  const float x = uv.x * float(m_width) - 0.5f;
  const float y = (1.0f - uv.y) * float(m_height) - 0.5f;
  if (!std::isfinite(x) || !std::isfinite(y)) return m_texels[0];
  const float fx = std::floor(x), fy = std::floor(y);
  const float tx = x - fx, ty = y - fy;
  // Repeat: indices modulo the size (fx may be far outside the image).
  const auto wrap = [](double i, int n) {
    const double m = std::fmod(i, double(n));
    return int(m < 0.0 ? m + double(n) : m) % n;
  };
  const int x0 = wrap(fx, m_width), y0 = wrap(fy, m_height);
  const int x1 = (x0 + 1) % m_width, y1 = (y0 + 1) % m_height;
  return (1.0f - ty) * ((1.0f - tx) * texel(x0, y0) + tx * texel(x1, y0)) +
         ty * ((1.0f - tx) * texel(x0, y1) + tx * texel(x1, y1));
}

Texture loadTexture(const std::string& path) {
  Image img;
  try {
    img = readImage(path);
  } catch (const std::exception& e) {
    throw Error(std::string("texture: ") + e.what());
  }
  Texture t(img.width, img.height, std::move(img.pixels));
  t.file = path;
  return t;
}

}  // namespace voxcone

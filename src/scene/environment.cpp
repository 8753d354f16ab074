// The environment light: lookups, the importance sampler and its density.

#include "voxcone/scene/environment.h"

#include "voxcone/core/error.h"
#include "voxcone/core/sampling.h"
#include "voxcone/image/image_io.h"

#include <algorithm>
#include <cmath>

namespace voxcone {

namespace {
/// The index i with cdf[i] <= u < cdf[i + 1] (cdf ascending from 0 to 1; empty intervals skipped).
size_t findInterval(const float* cdf, size_t n, float u) {
  const size_t i = size_t(std::upper_bound(cdf, cdf + n + 1, u) - cdf);
  return std::min(i == 0 ? 0 : i - 1, n - 1);
}
}  // namespace

Vec3 Environment::directionOf(float u, float v) {
  const float theta = kPi * v, alpha = 2.0f * kPi * (u - 0.5f);
  const float s = std::sin(theta);
  return Vec3(s * std::cos(alpha), std::cos(theta), s * std::sin(alpha));
}

Vec2 Environment::uvOf(const Vec3& d) {
  float u = 0.5f + std::atan2(d.z, d.x) * (0.5f * kInvPi);
  u -= std::floor(u);
  return Vec2(u, std::acos(std::clamp(d.y, -1.0f, 1.0f)) * kInvPi);
}

Environment Environment::constant(const Vec3& radiance) {
  if (!isFinite(radiance) || radiance.x < 0.0f || radiance.y < 0.0f || radiance.z < 0.0f)
    throw SettingsError("environment: the radiance must be finite and non-negative");
  Environment e;
  e.m_constant = radiance;
  e.m_integral = 4.0f * kPi * radiance;
  return e;
}

Environment Environment::image(int width, int height, std::vector<Vec3> texels, float scale, const glm::mat3& toWorld) {
  if (width < 1 || height < 1 || texels.size() != size_t(width) * size_t(height))
    throw SettingsError("environment: the map is empty");
  if (!std::isfinite(scale) || scale < 0.0f) throw SettingsError("environment: scale must be finite and non-negative");
  for (const Vec3& t : texels)
    if (!isFinite(t) || t.x < 0.0f || t.y < 0.0f || t.z < 0.0f)
      throw SettingsError("environment: the map has a negative or non-finite texel");
  Environment e;
  e.m_width = width;
  e.m_height = height;
  e.m_texels = std::move(texels);
  e.m_scale = scale;
  e.m_toWorld = toWorld;
  e.m_toLocal = glm::transpose(toWorld);
  // Each texel's weight: its luminance times its solid angle (2 pi / width)(cos theta0 - cos
  // theta1). Within a texel directions are drawn uniformly in solid angle, so the density is
  // the texel's probability over its solid angle: proportional to the radiance itself.
  const size_t W = size_t(width);
  e.m_rowCdf.assign((W + 1) * size_t(height), 0.0f);
  e.m_rowWeight.assign(size_t(height), 0.0f);
  e.m_marginalCdf.assign(size_t(height) + 1, 0.0f);
  DVec3 integral(0.0);
  double total = 0.0;
  for (int y = 0; y < height; ++y) {
    const double dOmega = 2.0 * kPi / double(width) *
                          (std::cos(kPi * double(y) / height) - std::cos(kPi * double(y + 1) / height));
    float* cdf = &e.m_rowCdf[size_t(y) * (W + 1)];
    double acc = 0.0;
    for (size_t x = 0; x < W; ++x) {
      const Vec3 L = scale * e.m_texels[size_t(y) * W + x];
      integral += DVec3(L) * dOmega;
      acc += double(luminance(L));
      cdf[x + 1] = float(acc);
    }
    for (size_t x = 1; x <= W; ++x) cdf[x] = acc > 0.0 ? float(double(cdf[x]) / acc) : float(double(x) / double(W));
    cdf[W] = 1.0f;
    e.m_rowWeight[size_t(y)] = float(acc * dOmega);
    total += acc * dOmega;
    e.m_marginalCdf[size_t(y) + 1] = float(total);
  }
  for (int y = 1; y <= height; ++y)
    e.m_marginalCdf[size_t(y)] = total > 0.0 ? float(double(e.m_marginalCdf[size_t(y)]) / total) : float(y) / height;
  e.m_marginalCdf[size_t(height)] = 1.0f;
  e.m_totalWeight = total;
  e.m_integral = Vec3(integral);
  return e;
}

Vec3 Environment::radiance(const Vec3& dir) const {
  if (isConstant()) return m_constant;
  const Vec2 uv = uvOf(m_toLocal * dir);
  const int x = std::min(int(uv.x * float(m_width)), m_width - 1);
  const int y = std::min(int(uv.y * float(m_height)), m_height - 1);
  return m_scale * m_texels[size_t(y) * size_t(m_width) + size_t(x)];
}

Vec3 Environment::sample(const Vec2& u, float& pdf) const {
  if (isConstant()) {
    pdf = kUniformSpherePdf;
    return sampleUniformSphere(u);
  }
  pdf = 0.0f;
  if (!(m_totalWeight > 0.0)) return Vec3(0.0f, 1.0f, 0.0f);
  const size_t H = size_t(m_height), W = size_t(m_width);
  const size_t y = findInterval(m_marginalCdf.data(), H, u.y);
  const float* cdf = &m_rowCdf[y * (W + 1)];
  const size_t x = findInterval(cdf, W, u.x);
  // Where u fell inside the chosen intervals: uniform within the texel.
  const auto within = [](const float* c, size_t i, float v) {
    const float w = c[i + 1] - c[i];
    return w > 0.0f ? std::clamp((v - c[i]) / w, 0.0f, 1.0f) : 0.5f;
  };
  const float du = within(cdf, x, u.x), dv = within(m_marginalCdf.data(), y, u.y);
  const float c0 = std::cos(kPi * float(y) / float(H)), c1 = std::cos(kPi * float(y + 1) / float(H));
  const float cosT = c0 - dv * (c0 - c1);
  const float sinT = safeSqrt(1.0f - cosT * cosT);
  const float alpha = 2.0f * kPi * ((float(x) + du) / float(W) - 0.5f);
  const Vec3 local(sinT * std::cos(alpha), cosT, sinT * std::sin(alpha));
  const float texelProb = (cdf[x + 1] - cdf[x]) * (m_marginalCdf[y + 1] - m_marginalCdf[y]);
  const float dOmega = 2.0f * kPi / float(W) * (c0 - c1);
  pdf = dOmega > 0.0f ? texelProb / dOmega : 0.0f;
  return glm::normalize(m_toWorld * local);
}

float Environment::pdf(const Vec3& dir) const {
  if (isConstant()) return kUniformSpherePdf;
  if (!(m_totalWeight > 0.0)) return 0.0f;
  const Vec2 uv = uvOf(m_toLocal * dir);
  const size_t W = size_t(m_width), H = size_t(m_height);
  const size_t x = std::min(size_t(uv.x * float(W)), W - 1), y = std::min(size_t(uv.y * float(H)), H - 1);
  const float* cdf = &m_rowCdf[y * (W + 1)];
  const float texelProb = (cdf[x + 1] - cdf[x]) * (m_marginalCdf[y + 1] - m_marginalCdf[y]);
  const float dOmega = 2.0f * kPi / float(W) * (std::cos(kPi * float(y) / float(H)) - std::cos(kPi * float(y + 1) / float(H)));
  return dOmega > 0.0f ? texelProb / dOmega : 0.0f;
}

Environment loadEnvironmentMap(const std::string& path, float scale, const glm::mat3& toWorld) {
  Image img = readImage(path);
  Environment e = Environment::image(img.width, img.height, std::move(img.pixels), scale, toWorld);
  e.file = path;
  return e;
}

glm::mat3 rotationY(float degrees) {
  const float a = glm::radians(degrees), c = std::cos(a), s = std::sin(a);
  // Columns: the images of +x, +y, +z.
  return glm::mat3(Vec3(c, 0.0f, -s), Vec3(0.0f, 1.0f, 0.0f), Vec3(s, 0.0f, c));
}

bool isRotation(const glm::mat3& m) {
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      if (!(std::fabs(glm::dot(m[i], m[j]) - (i == j ? 1.0f : 0.0f)) < 1e-3f)) return false;
  return glm::determinant(m) > 0.0f;
}

}  // namespace voxcone

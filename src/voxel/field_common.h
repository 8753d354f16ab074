#pragma once
/// \file field_common.h (private to src/voxel/)
/// What the field's files share that needs no OpenVDB: the compact encodings of a voxel's
/// attributes, the decoded record a cone lookup reads, the levels that keep flat tables, and
/// the cube a field covers.

#include "voxcone/core/math.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>

namespace voxcone {

class Scene;

namespace voxel {

// ---- compact encodings ----

/// Octahedral encoding of a unit vector in 2 x 8 bits.
inline uint16_t encodeNormal(const Vec3& n) {
  const float l1 = std::abs(n.x) + std::abs(n.y) + std::abs(n.z);
  if (!(l1 > 0.0f)) return encodeNormal(Vec3(0.0f, 0.0f, 1.0f));
  float x = n.x / l1, y = n.y / l1;
  if (n.z < 0.0f) {
    const float ox = (1.0f - std::abs(y)) * (x >= 0.0f ? 1.0f : -1.0f);
    const float oy = (1.0f - std::abs(x)) * (y >= 0.0f ? 1.0f : -1.0f);
    x = ox;
    y = oy;
  }
  auto q = [](float v) { return uint16_t(std::lround((std::clamp(v, -1.0f, 1.0f) * 0.5f + 0.5f) * 254.0f)); };
  return uint16_t(q(x) | (q(y) << 8));
}
/// The octahedral decode before normalization: the direction, not unit length.
inline Vec3 decodeNormalDirection(uint16_t code) {
  const float x = float(code & 0xffu) / 254.0f * 2.0f - 1.0f;
  const float y = float(code >> 8) / 254.0f * 2.0f - 1.0f;
  Vec3 n(x, y, 1.0f - std::abs(x) - std::abs(y));
  const float t = std::max(-n.z, 0.0f);
  n.x += n.x >= 0.0f ? -t : t;
  n.y += n.y >= 0.0f ? -t : t;
  return n;
}
inline Vec3 decodeNormal(uint16_t code) { return glm::normalize(decodeNormalDirection(code)); }
inline uint8_t encodeUnorm8(float v) { return uint8_t(std::lround(std::clamp(v, 0.0f, 1.0f) * 255.0f)); }
/// RGB9E5 (OpenGL EXT_texture_shared_exponent): three 9-bit mantissas, one 5-bit exponent.
/// Values saturate at 65408 instead of overflowing; negatives clamp to 0.
inline uint32_t encodeRgb9e5(const Vec3& rgb) {
  constexpr float kMax = 65408.0f;  // (2^9 - 1) / 2^9 * 2^(31 - 15)
  const float r = std::clamp(rgb.x, 0.0f, kMax), g = std::clamp(rgb.y, 0.0f, kMax), b = std::clamp(rgb.z, 0.0f, kMax);
  const float maxc = std::max(r, std::max(g, b));
  if (!(maxc > 0.0f)) return 0;
  int e2 = 0;
  std::frexp(maxc, &e2);                             // maxc = f * 2^e2, f in [0.5, 1)
  int exp = std::max(-16, e2 - 1) + 1 + 15;          // shared biased exponent
  if (std::floor(maxc / std::ldexp(1.0f, exp - 15 - 9) + 0.5f) >= 512.0f) ++exp;
  const float scale = std::ldexp(1.0f, exp - 15 - 9);
  auto m = [&](float v) { return std::min(511u, uint32_t(std::floor(v / scale + 0.5f))); };
  return m(r) | (m(g) << 9) | (m(b) << 18) | (uint32_t(exp) << 27);
}
inline Vec3 decodeRgb9e5(uint32_t code) {
  // 2^(exponent - 15 - 9) built from its bits: biased exponent field (code >> 27) - 24 + 127,
  // always in [103, 134], a normal float (std::ldexp was a tenth of the cone lookups' time).
  const uint32_t bits = ((code >> 27) + 103u) << 23;
  float scale;
  std::memcpy(&scale, &bits, sizeof scale);
  return Vec3(float(code & 511u), float((code >> 9) & 511u), float((code >> 18) & 511u)) * scale;
}
inline float decodeUnorm8(uint8_t v) { return float(v) * (1.0f / 255.0f); }

inline constexpr double kPiD = 3.14159265358979323846;

/// What a cone lookup reads of one voxel, decoded once (Level::coneTable).
struct ConeVoxel {
  Vec3 projected;  ///< opacity times the axis fractions (|normal| per axis at the finest level)
  Vec3 side;       ///< the normal's direction (not normalized): which side a viewer sees
  Vec3 front, back;///< radiance of the side the normal points to, and of the other
};
static_assert(sizeof(ConeVoxel) == 48, "ConeVoxel is 12 floats");

/// Levels that keep a flat brick table (Level::denseBricks): 4 bytes per brick of the whole cube,
/// 1 MB at level 8; finer levels probe the tree.
inline constexpr int kDenseBrickLevel = 8;
/// Levels that keep decoded cone-lookup attributes (Level::coneTable, 48 bytes per voxel: 1.2 MB
/// for cornell-dragon's 25k voxels at level 6, 15 MB at level 8, so not there). Measured on
/// cornell-box at level 6: cone gathers 21% faster, the same image to 4 digits of PSNR.
inline constexpr int kConeTableLevel = 7;

/// The cube a field of `scene` covers: its bounds' lower corner less the padding, its longest
/// side plus twice the padding (voxel_field.cpp).
void fieldCube(const Scene& scene, double padding, DVec3& origin, double& extent);

/// A hash of what a field's content depends on (scene_hash.cpp): a field read back serves only
/// the scene it was built for.
uint64_t fieldSceneHash(const Scene& scene);

/// "123 MB".
std::string megabytes(uint64_t bytes);

}  // namespace voxel
}  // namespace voxcone

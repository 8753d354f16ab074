#pragma once
/// \file math.h
/// Vector types (GLM), constants and small helpers shared by every stage.

#include <glm/glm.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

namespace voxcone {

using Vec2 = glm::vec2;
using Vec3 = glm::vec3;
using Vec4 = glm::vec4;
using DVec3 = glm::dvec3;
using UVec3 = glm::uvec3;

constexpr float kPi = 3.14159265358979323846f;
constexpr float kInvPi = 1.0f / kPi;
constexpr float kInv2Pi = 0.5f / kPi;
constexpr float kInf = std::numeric_limits<float>::infinity();

/// Largest float strictly less than one: keeps samples in [0,1).
constexpr float kOneMinusEpsilon = 0x1.fffffep-1f;

/// Rec. 709 luminance of a linear RGB value.
inline float luminance(const Vec3& rgb) { return 0.2126f * rgb.x + 0.7152f * rgb.y + 0.0722f * rgb.z; }

/// Largest component.
inline float maxComponent(const Vec3& v) { return std::max(v.x, std::max(v.y, v.z)); }

/// Index (0,1,2) of the largest component.
inline int maxDimension(const Vec3& v) { return (v.x > v.y) ? (v.x > v.z ? 0 : 2) : (v.y > v.z ? 1 : 2); }

inline bool isBlack(const Vec3& v) { return v.x == 0.0f && v.y == 0.0f && v.z == 0.0f; }

inline bool isFinite(const Vec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

template <typename T> inline T sqr(T x) { return x * x; }

inline float safeSqrt(float x) { return std::sqrt(std::max(0.0f, x)); }

/// The largest power of two <= x, for a normal float x > 0: x with its mantissa bits cleared
/// (exp2(floor(log2(x))) without the two library calls).
inline float floorPow2(float x) {
  uint32_t bits;
  std::memcpy(&bits, &x, sizeof(float));
  bits &= 0xff800000u;
  std::memcpy(&x, &bits, sizeof(float));
  return x;
}

/// The smallest power of two >= x, for a normal float x > 0 (exp2(ceil(log2(x)))).
inline float ceilPow2(float x) {
  const float f = floorPow2(x);
  return f == x ? x : 2.0f * f;
}

/// Orthonormal frame around a unit normal (Duff et al. 2017, "Building an Orthonormal Basis,
/// Revisited", JCGT 6(1)). Local z is the normal.
struct Frame {
  Vec3 s, t, n;
  Frame() : s(1, 0, 0), t(0, 1, 0), n(0, 0, 1) {}
  explicit Frame(const Vec3& normal) : n(normal) {
    const float sign = std::copysign(1.0f, n.z);
    const float a = -1.0f / (sign + n.z);
    const float b = n.x * n.y * a;
    s = Vec3(1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x);
    t = Vec3(b, sign + n.y * n.y * a, -n.y);
  }
  Vec3 toLocal(const Vec3& v) const { return Vec3(glm::dot(v, s), glm::dot(v, t), glm::dot(v, n)); }
  Vec3 toWorld(const Vec3& v) const { return s * v.x + t * v.y + n * v.z; }
};

}  // namespace voxcone

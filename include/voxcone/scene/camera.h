#pragma once
/// \file camera.h
/// Pinhole camera.

#include "voxcone/core/ray.h"

namespace voxcone {

/// A pinhole camera looking from `position` towards `target`. The image x axis points along
/// cross(forward, up) (right-handed): for the Cornell box camera (+z forward, +y up) image
/// right is world -x, so the red wall at x = 556 is on the left.
class Camera {
public:
  Camera() = default;
  /// fovYDeg: vertical field of view in degrees, (0, 180).
  Camera(const Vec3& position, const Vec3& target, const Vec3& up, float fovYDeg);

  /// Primary ray through film position (px, py) in pixels, (0,0) the top-left corner of the
  /// image of width x height pixels. The direction is normalized.
  Ray generateRay(float px, float py, int width, int height) const;

  const Vec3& position() const { return m_position; }
  const Vec3& target() const { return m_target; }
  const Vec3& up() const { return m_up; }
  float fovYDeg() const { return m_fovYDeg; }
  /// Unit viewing direction (the depth AOV's axis).
  const Vec3& forward() const { return m_forward; }

private:
  Vec3 m_position{0.0f}, m_target{0.0f, 0.0f, 1.0f}, m_up{0.0f, 1.0f, 0.0f};
  float m_fovYDeg = 45.0f;
  Vec3 m_forward{0.0f, 0.0f, 1.0f}, m_right{-1.0f, 0.0f, 0.0f}, m_upOrtho{0.0f, 1.0f, 0.0f};
  float m_tanHalfFov = 0.41421356f;
};

}  // namespace voxcone

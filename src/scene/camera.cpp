#include "voxcone/scene/camera.h"

#include "voxcone/core/error.h"

namespace voxcone {

Camera::Camera(const Vec3& position, const Vec3& target, const Vec3& up, float fovYDeg)
    : m_position(position), m_target(target), m_up(up), m_fovYDeg(fovYDeg) {
  m_forward = glm::normalize(target - position);
  m_right = glm::normalize(glm::cross(m_forward, up));
  m_upOrtho = glm::cross(m_right, m_forward);
  m_tanHalfFov = std::tan(0.5f * glm::radians(fovYDeg));
}

Ray Camera::generateRay(float px, float py, int width, int height) const {
  // Film plane at distance 1: x in [-aspect, aspect] * tan(fov/2), y in [-1, 1] * tan(fov/2).
  const float aspect = static_cast<float>(width) / static_cast<float>(height);
  const float sx = (2.0f * px / static_cast<float>(width) - 1.0f) * aspect * m_tanHalfFov;
  const float sy = (1.0f - 2.0f * py / static_cast<float>(height)) * m_tanHalfFov;
  Ray r;
  r.origin = m_position;
  r.dir = glm::normalize(m_forward + sx * m_right + sy * m_upOrtho);
  return r;
}

}  // namespace voxcone

#pragma once
/// \file light_proximity.h
/// How near a surface point is to a light, for splitting the light that leaves surfaces beside a
/// lamp off voxcone's cones (voxel_cone.h, `near_light`).
///
/// A cone's exact ray takes the radiance of the one point it hits for the whole cone. Where that
/// point sits beside a lamp (a ceiling 2 cm above a lamp's top, lit to many times the radiance
/// of anything else in the room, and seen through a 2 cm gap), one cone in thousands hits it and
/// carries a hundred times the light the cone's solid angle truly receives from it: the gathers'
/// light came out with 32x32 blocks 10-57% apart from seed to seed. So the light leaving a
/// point y is split by y's distance d to the nearest light: a cone that hits y takes the share
///   w(d) = min(1, (d / r)^2)
/// and photons that left y (their last diffuse bounce, Photon::nearShare = 1 - w) carry the rest
/// to the gathering point, where a photon estimate takes it (as the caustic map takes the light
/// that mirrors concentrate). The two add up to all of it for any r.

#include "voxcone/core/math.h"

#include <cstdint>
#include <unordered_map>
#include <vector>

namespace voxcone {

class Scene;

class LightProximity {
public:
  LightProximity() = default;
  /// Over `scene`'s emissive triangles and point lights, within `radius` (world units, > 0).
  LightProximity(const Scene& scene, float radius);
  bool empty() const { return m_tris.empty(); }
  float radius() const { return m_radius; }
  /// Distance from p to the nearest light, or infinity where none lies within radius().
  float distance(const Vec3& p) const;
  /// The share of the light leaving p that cones take: min(1, (d / radius)^2); 1 with no lights.
  float coneShare(const Vec3& p) const {
    const float d = distance(p);
    return d >= m_radius ? 1.0f : sqr(d / m_radius);
  }
  /// The point of triangle (a, b, c) nearest to p (Ericson, Real-Time Collision Detection 5.1.5).
  static Vec3 closestOnTriangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c);

private:
  struct Tri {
    Vec3 a, b, c;  ///< a point light: a = b = c
  };
  uint64_t key(int x, int y, int z) const;
  std::vector<Tri> m_tris;
  /// Cells of side m_cell: the lights whose bounds, grown by the radius, overlap each.
  std::unordered_map<uint64_t, std::vector<uint32_t>> m_cells;
  float m_radius = 0.0f, m_cell = 1.0f;
};

}  // namespace voxcone

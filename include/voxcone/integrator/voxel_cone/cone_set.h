#pragma once
/// \file cone_set.h
/// The cones a diffuse shading point gathers indirect light with, and their weights.
///
/// N cone axes are spread over the hemisphere around +z with equal solid angle per cone (a
/// spherical Fibonacci spiral: z_i = 1 - (i + 1/2) / N, phi_i = i * golden angle). Each
/// cone stands for the directions nearer to its axis than to any other (its Voronoi cell on
/// the hemisphere), so its weight is the cosine-weighted measure of that cell,
/// w_i = (1/pi) * integral over cell_i of cos(theta) d omega, and sum_i w_i = 1: under a
/// uniform radiance L every cone returns L and a Lambertian surface reflects albedo * L, the
/// furnace result. The weights are integrated numerically once (stratified cosine-distributed
/// directions assigned to their nearest axis), not tuned.
///
/// The default half-angle gives every cone the solid angle of its cell, 2 pi / N:
/// theta = acos(1 - 1/N) (6 cones: 33.6 degrees, 16 cones: 20.4 degrees).

#include "voxcone/core/math.h"

#include <vector>

namespace voxcone {

struct Cone {
  Vec3 axis{0.0f, 0.0f, 1.0f};  ///< unit, local frame (+z = surface normal)
  float weight = 0.0f;          ///< cosine-weighted share of the hemisphere, sums to 1
};

class ConeSet {
public:
  ConeSet() = default;  ///< no cones
  /// `count` cones in [1, 256]; halfAngle in radians, <= 0 for the default acos(1 - 1/N).
  ConeSet(int count, float halfAngle);
  const std::vector<Cone>& cones() const { return m_cones; }
  float halfAngle() const { return m_halfAngle; }
  /// The default half-angle for `count` cones.
  static float defaultHalfAngle(int count);

private:
  std::vector<Cone> m_cones;
  float m_halfAngle = 0.0f;
};

}  // namespace voxcone

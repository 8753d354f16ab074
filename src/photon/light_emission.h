#pragma once
/// \file light_emission.h
/// Sampling photon emission (a point and a direction leaving a light) for the photon tracer.
/// Scene samples lights towards a shading point only; emission is computed here from Scene's
/// public fields, with the same light set and the same choice by power as Scene::finalize
/// (every emissive triangle and every point light is one light, chosen in proportion to the
/// luminance of its flux).

#include "voxcone/core/bounds.h"
#include "voxcone/core/math.h"
#include "voxcone/core/ray.h"

#include <cstdint>
#include <vector>

namespace voxcone {

class Scene;

/// A photon leaving a light.
struct EmittedPhoton {
  Ray ray;               ///< origin offset off the emitter's surface, unit direction
  /// Flux estimate of this one sample, W per channel: the chosen light's RGB flux divided by
  /// the probability of choosing it. Its expectation over the choice is the total flux.
  DVec3 fluxWatts{0.0};
  bool environment = false;  ///< it left the environment (the sky)
};

/// The lights of a scene with their flux and the power distribution used to choose them.
class LightEmission {
public:
  /// Collects the emissive triangles (positive area and flux), the point lights with positive
  /// luminance of intensity, the directional lights with positive luminance of irradiance
  /// (emitting from a disc that covers the scene's bounding sphere, pbrt's distant light) and
  /// the environment (from such a disc facing each direction it draws); with `localOnly` the
  /// lamps alone (emissive triangles and point lights).
  explicit LightEmission(const Scene& scene, bool localOnly = false);

  /// Distant lights (directional, environment) then emit a share `share` in (0, 1) of their
  /// photons from the disc of `target`'s radius around its centre's projection (what the camera
  /// looks at) and the rest from the whole disc, each photon weighted by the mixture's density
  /// at its point: unbiased, as the whole disc keeps 1 - share. A target of negative radius (or
  /// one that covers the scene's sphere) leaves emission as it was.
  void setDistantTarget(const Sphere& target, double share);

  /// True when no light emits anything (no photon can be emitted).
  bool empty() const { return m_cdf.empty(); }
  /// Number of lights that can be chosen.
  size_t lightCount() const { return m_cdf.size(); }
  /// Sum of every light's flux, W per channel (Lambertian emitter: pi * Le * area per
  /// emitting side; point light: 4 pi I; directional: E pi R^2, R the bounding sphere's;
  /// environment: pi R^2 times the integral of its radiance over the sphere).
  const DVec3& totalFlux() const { return m_totalFlux; }
  /// Probability of choosing light `i` (emissive triangles first, then point lights).
  double pmf(size_t i) const { return m_pmf[i]; }
  /// Whether light `i` is a lamp (an emissive triangle or a point light), not a sun or the sky.
  bool local(size_t i) const { return m_lights[i].directional < 0 && !m_lights[i].environment; }

  /// Sample an emitted photon. uLight in [0,1) chooses the light (double, so that lights of
  /// probability below float resolution keep their share), uSide in [0,1) the side of a
  /// two-sided emitter, uPos in [0,1)^2 the point on a triangle, uDir in [0,1)^2 the direction
  /// (for a directional light, whose direction is fixed, the point on its disc; for the
  /// environment the direction, and uPos the point on its disc).
  /// Returns false when nothing is emitted (no lights).
  bool sample(double uLight, float uSide, const Vec2& uPos, const Vec2& uDir, EmittedPhoton& out) const;
  /// The same light and point, but the direction uniform in the cone from that point towards
  /// `target` (a sphere), the flux weighted by the cone's solid angle over the emitted
  /// cosine: unbiased for every path whose first hit lies in the sphere. From a point inside
  /// the sphere, sample()'s direction. Returns false also when the direction leaves a one-sided
  /// emitter's back (the photon carries nothing).
  bool sampleToward(double uLight, float uSide, const Vec2& uPos, const Vec2& uDir, const Sphere& target,
                    EmittedPhoton& out) const;

private:
  struct Light {
    uint32_t triangle = 0;   ///< emissive triangle, or
    int32_t pointLight = -1; ///< index in Scene::pointLights (>= 0 for a point light)
    int32_t directional = -1;///< index in Scene::directionalLights (>= 0 for a directional light)
    bool environment = false;///< the scene's environment
    DVec3 fluxWatts{0.0};
    bool twoSided = false;
  };
  /// The light uLight in [0,1) chooses, by power.
  size_t choose(double uLight) const;
  /// A uniform point on emissive triangle `light` (its rounding bound in pError) and the
  /// triangle's front (winding) normal.
  Vec3 pointOn(const Light& light, const Vec2& uPos, Vec3& pError, Vec3& frontNormal) const;

  /// An environment photon (light `idx`): its direction from the environment's sampler with
  /// uDir, its origin (uPos) on the disc of `radius` facing it, beyond the bounding sphere,
  /// centred on the line through `centre` along it (discPoint: with `targeted`, the distant
  /// target's mixture, uChoice picking its part).
  bool sampleEnvironment(size_t idx, bool targeted, float uChoice, const Vec2& uPos, const Vec2& uDir,
                         const Vec3& centre, float radius, EmittedPhoton& out) const;

  /// The disc a directional light emits from: centred on the bounding sphere's axis along the
  /// light, a little outside the sphere, radius R.
  Vec3 discCentre(const Vec3& direction) const;
  /// A point of the emitting disc across direction d: uniform (u) on the disc of `radius` around
  /// `centre`'s projection, or, with `targeted` and a distant target set, from the mixture of
  /// that disc and the target's (uChoice picks the part); and the area density there.
  Vec3 discPoint(const Vec3& d, const Vec3& centre, float radius, bool targeted, float uChoice, const Vec2& u,
                 double& areaPdf) const;

  const Scene& m_scene;
  Sphere m_sphere;  ///< the scene's bounding sphere
  std::vector<Light> m_lights;
  Sphere m_distantTarget;        ///< setDistantTarget's (radius < 0: none)
  double m_distantShare = 0.0;
  std::vector<double> m_cdf;   ///< cumulative choice probability, the last entry exactly 1
  std::vector<double> m_pmf;
  DVec3 m_totalFlux{0.0};
};

}  // namespace voxcone

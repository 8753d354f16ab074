#pragma once
/// \file path.h
/// The reference integrator: unbiased unidirectional path tracing with next-event estimation,
/// multiple importance sampling (power heuristic; Veach 1997, ch. 9) and Russian roulette.

#include "voxcone/integrator/integrator.h"

namespace voxcone {

/// Path tracer. Options: `rr_depth` (bounces before Russian roulette starts, default 3),
/// `light_sampling` ("nee", the default: next-event estimation with MIS; "none": BSDF sampling
/// alone, emission counted where paths hit it: far noisier, but sharing no light-sampling or
/// shadow-ray code with the default, which the tests compare it with region by region).
class PathIntegrator final : public Integrator {
public:
  explicit PathIntegrator(const IntegratorContext& context);
  std::string name() const override { return "path"; }
  Vec3 li(const Ray& ray, Sampler& sampler) const override;
  bool separatesTerms() const override { return true; }
  Vec3 liTerms(const Ray& ray, Sampler& sampler, IndirectSplit* split, RadianceTerms& terms) const override;
  nlohmann::json settingsJson() const override;

private:
  /// li, each contribution also added to its term when `terms` is given (RadianceTerms: by
  /// the path's vertices, emission before any non-delta vertex is emitted, light reaching the
  /// first non-delta vertex from a light is direct, or caustic through delta vertices, the
  /// rest indirect). The same samples and the same sum either way.
  Vec3 trace(const Ray& ray, Sampler& sampler, RadianceTerms* terms) const;

  const Scene& m_scene;
  const Accel& m_accel;
  int m_maxDepth;
  int m_rrDepth = 3;
  bool m_nee = true;
  int m_lightSamples = 1;  ///< light samples per vertex (stratified over the light choice)
};

}  // namespace voxcone

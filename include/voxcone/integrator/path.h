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
  nlohmann::json settingsJson() const override;

private:
  const Scene& m_scene;
  const Accel& m_accel;
  int m_maxDepth;
  int m_rrDepth = 3;
  bool m_nee = true;
};

}  // namespace voxcone

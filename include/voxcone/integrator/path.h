#pragma once
/// \file path.h
/// The reference integrator: unbiased unidirectional path tracing with next-event estimation,
/// multiple importance sampling (power heuristic; Veach 1997, ch. 9) and Russian roulette.

#include "voxcone/integrator/integrator.h"

namespace voxcone {

/// Path tracer. Options: `rr_depth` (bounces before Russian roulette starts, default 3).
class PathIntegrator final : public Integrator {
public:
  explicit PathIntegrator(const IntegratorContext& context);
  std::string name() const override { return "path"; }
  Vec3 li(const Ray& ray, Rng& rng) const override;
  nlohmann::json settingsJson() const override;

private:
  const Scene& m_scene;
  const Accel& m_accel;
  int m_maxDepth;
  int m_rrDepth = 3;
};

}  // namespace voxcone

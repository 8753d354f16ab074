#pragma once
/// \file whitted.h
/// Whitted-style ray tracing (Whitted 1980): direct light with shadow rays at non-delta
/// surfaces, recursive specular reflection and refraction at delta surfaces, no diffuse
/// interreflection. The exact-hit skeleton the voxel-cone integrator extends. Its direct light:
/// estimateDirectLight (direct_light.h).

#include "voxcone/integrator/integrator.h"

namespace voxcone {

/// Whitted integrator. Options: `light_samples` (shadow rays per shading point, default 1).
class WhittedIntegrator final : public Integrator {
public:
  explicit WhittedIntegrator(const IntegratorContext& context);
  std::string name() const override { return "whitted"; }
  Vec3 li(const Ray& ray, Sampler& sampler) const override;
  bool separatesTerms() const override { return true; }
  Vec3 liTerms(const Ray& ray, Sampler& sampler, IndirectSplit* split, RadianceTerms& terms) const override;
  nlohmann::json settingsJson() const override;

private:
  const Scene& m_scene;
  const Accel& m_accel;
  int m_maxDepth;
  int m_lightSamples = 1;
};

}  // namespace voxcone

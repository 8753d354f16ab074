#include "voxcone/integrator/whitted.h"

#include "delta_chain.h"
#include "options.h"
#include "voxcone/accel/accel.h"
#include "voxcone/integrator/direct_light.h"

namespace voxcone {

WhittedIntegrator::WhittedIntegrator(const IntegratorContext& c)
    : m_scene(c.scene), m_accel(c.accel), m_maxDepth(c.settings.maxDepth) {
  OptionReader r(c.options, "whitted");
  m_lightSamples = r.integer("light_samples", 1, 1, 1024);
  r.finish();
}

nlohmann::json WhittedIntegrator::settingsJson() const {
  return {{"max_depth", m_maxDepth}, {"light_samples", m_lightSamples}};
}

Vec3 WhittedIntegrator::li(const Ray& ray, Sampler& sampler) const {
  RadianceTerms unused;
  return liTerms(ray, sampler, nullptr, unused);
}

Vec3 WhittedIntegrator::liTerms(const Ray& ray, Sampler& sampler, IndirectSplit*, RadianceTerms& terms) const {
  const auto direct = [this, &terms](const SurfaceHit& sh, const Vec3& wo, Sampler& px, int, const Vec3& weight) {
    const Vec3 L = estimateDirectLight(m_scene, m_accel, sh, wo, px, m_lightSamples);
    terms.direct += weight * L;
    return L;
  };
  return traceDeltaChains(m_scene, m_accel, ray, sampler, m_maxDepth, m_maxDepth, true, direct, &terms);
}

}  // namespace voxcone

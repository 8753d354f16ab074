#include "voxcone/integrator/whitted.h"

#include "options.h"
#include "voxcone/accel/hbvh.h"
#include "voxcone/scene/bsdf.h"

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

Vec3 estimateDirectLight(const Scene& scene, const Hbvh& accel, const SurfaceHit& hit, const Vec3& woWorld, Rng& rng,
                         int samples) {
  const Material& mat = scene.materials[hit.material];
  const Frame frame(hit.shadingNormal);
  const Vec3 wo = frame.toLocal(woWorld);
  Vec3 sum(0.0f);
  for (int i = 0; i < samples; ++i) {
    const float uc = rng.uniform();
    const Vec2 u = rng.uniform2();
    const LightSample ls = scene.sampleLight(hit.position, uc, u);
    if (!(ls.pdf > 0.0f)) continue;
    const Vec3 wi = frame.toLocal(ls.wi);
    const Vec3 f = bsdfEval(mat, wo, wi) * std::fabs(wi.z);
    if (isBlack(f)) continue;
    if (accel.occluded(spawnRayTo(hit.position, hit.geomNormal, ls.lightPos))) continue;
    sum += f * ls.radiance / ls.pdf;
  }
  return sum / static_cast<float>(samples);
}

Vec3 WhittedIntegrator::li(const Ray& ray, Rng& rng) const { return trace(ray, rng, 0, 1.0f); }

Vec3 WhittedIntegrator::trace(const Ray& ray, Rng& rng, int depth, float throughput) const {
  const std::optional<Hit> hit = m_accel.intersect(ray);
  if (!hit) return Vec3(0.0f);
  const Vec3 pos = ray.at(hit->t);
  const SurfaceHit sh = m_scene.surfaceAt(hit->triangle, pos, hit->b1, hit->b2);
  const Vec3 woWorld = -glm::normalize(ray.dir);
  Vec3 L = m_scene.emitted(sh, woWorld);
  const Material& mat = m_scene.materials[sh.material];
  if (!mat.isDelta()) return L + estimateDirectLight(m_scene, m_accel, sh, woWorld, rng, m_lightSamples);
  if (depth + 1 >= m_maxDepth) return L;
  // Delta surface: follow every lobe (reflection and refraction both, for glass).
  const Frame frame(sh.shadingNormal);
  DeltaLobe lobes[2];
  const int n = bsdfDeltaLobes(mat, frame.toLocal(woWorld), lobes);
  for (int i = 0; i < n; ++i) {
    // Splitting at every dielectric doubles the rays per level; drop branches whose
    // accumulated weight is below 1/1000 (they cannot change the pixel visibly).
    const float branch = throughput * maxComponent(lobes[i].weight);
    if (branch < 1e-3f) continue;
    const Ray next = spawnRay(pos, sh.geomNormal, frame.toWorld(lobes[i].wi));
    L += lobes[i].weight * trace(next, rng, depth + 1, branch);
  }
  return L;
}

}  // namespace voxcone

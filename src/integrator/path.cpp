#include "voxcone/integrator/path.h"

#include "options.h"
#include "voxcone/accel/accel.h"
#include "voxcone/core/sampling.h"
#include "voxcone/scene/bsdf.h"

namespace voxcone {

PathIntegrator::PathIntegrator(const IntegratorContext& c)
    : m_scene(c.scene), m_accel(c.accel), m_maxDepth(c.settings.maxDepth) {
  OptionReader r(c.options, "path");
  m_rrDepth = r.integer("rr_depth", 3, 0, 1024);
  m_nee = r.choice("light_sampling", {"nee", "none"}) == "nee";
  m_lightSamples = r.integer("light_samples", 1, 1, 64);
  r.finish();
}

nlohmann::json PathIntegrator::settingsJson() const {
  return {{"max_depth", m_maxDepth},
          {"rr_depth", m_rrDepth},
          {"light_sampling", m_nee ? "nee" : "none"},
          {"light_samples", m_lightSamples}};
}

Vec3 PathIntegrator::li(const Ray& ray, Sampler& sampler) const { return trace(ray, sampler, nullptr); }

Vec3 PathIntegrator::liTerms(const Ray& ray, Sampler& sampler, IndirectSplit*, RadianceTerms& terms) const {
  return trace(ray, sampler, &terms);
}

Vec3 PathIntegrator::trace(const Ray& cameraRay, Sampler& sampler, RadianceTerms* terms) const {
  Vec3 L(0.0f), beta(1.0f);
  int diffuseVertices = 0;       // non-delta vertices so far (terms)
  bool deltaSinceDiffuse = false;// a delta vertex after the first non-delta one (terms)
  // Which term light arriving at the current vertex from a light belongs to.
  const auto term = [&](bool viaDelta) -> Vec3* {
    if (diffuseVertices == 0) return &terms->emitted;
    if (diffuseVertices > 1) return &terms->indirect;
    return viaDelta ? &terms->caustic : &terms->direct;
  };
  Ray ray = cameraRay;
  bool specularBounce = true;  // the camera vertex acts as a delta
  float prevPdf = 0.0f;        // solid-angle pdf of the BSDF sample that made `ray`
  Vec3 prevPos(0.0f);
  Vec3 prevNormal(0.0f, 0.0f, 1.0f);  // its shading normal (the light tree's bound)
  float etaScale = 1.0f;       // removes radiance's 1/eta^2 from the roulette weight

  for (int depth = 0;; ++depth) {
    SurfaceHit sh;
    if (!intersectSurface(m_scene, m_accel, ray, sh)) {
      // The ray leaves the scene: the environment's radiance, MIS-weighted as emission is.
      const Vec3 dir = glm::normalize(ray.dir);
      const Vec3 Le = specularBounce || !m_nee ? m_scene.escaped(dir) : m_scene.escapedMis(dir, prevPdf / float(m_lightSamples));
      if (!isBlack(Le)) {
        const Vec3 c = beta * Le;
        L += c;
        if (terms) *term(deltaSinceDiffuse) += c;
      }
      break;
    }
    const Vec3& pos = sh.position;
    const Vec3 woWorld = -glm::normalize(ray.dir);

    // Emission found by BSDF sampling, MIS-weighted against light sampling.
    const Vec3 Le = m_scene.emitted(sh, woWorld);
    if (!isBlack(Le)) {
      Vec3 c;
      if (specularBounce || !m_nee) {
        c = beta * Le;
      } else {
        const float lightPdf = m_scene.lightPdf(prevPos, &prevNormal, sh.triangle, pos, sh.geomNormal);
        c = beta * Le * powerHeuristic(prevPdf, float(m_lightSamples) * lightPdf);
      }
      L += c;
      if (terms) *term(deltaSinceDiffuse) += c;
    }
    if (depth + 1 >= m_maxDepth) break;

    Material textured;
    const Material& mat = m_scene.materialAt(sh, textured);
    const Frame frame(sh.shadingNormal);
    const Vec3 wo = frame.toLocal(woWorld);

    // Next-event estimation: light_samples light samples, their choice stratified (one pair
    // shifted by i / n in u.x), each MIS-weighted against BSDF sampling (Veach's multi-sample
    // power heuristic); with the light tree's splitting each takes one light per group.
    if (m_nee && !mat.isDelta()) {
      const Vec2 u0 = sampler.uniform2();
      const float nl = float(m_lightSamples);
      for (int i = 0; i < m_lightSamples; ++i) {
        const Vec2 ui(std::min((float(i) + u0.x) / nl, kOneMinusEpsilon), u0.y);
        LightSample samples[LightTree::kMaxChoices];
        const int count = m_scene.sampleLights(pos, ui, true, nullptr, &sh.shadingNormal, samples);
        for (int k = 0; k < count; ++k) {
          const LightSample& ls = samples[k];
          if (!(ls.pdf > 0.0f)) continue;
          const Vec3 wi = frame.toLocal(ls.wi);
          const Vec3 f = bsdfEval(mat, wo, wi) * std::fabs(wi.z);
          if (isBlack(f)) continue;
          const Ray shadow =
              spawnRayTo(pos, sh.positionError, sh.geomNormal, ls.lightPos, ls.lightPosError, ls.lightNormal);
          if (m_accel.occluded(shadow)) continue;
          const float w = ls.delta ? 1.0f : powerHeuristic(nl * ls.pdf, bsdfPdf(mat, wo, wi));
          const Vec3 c = beta * f * ls.radiance * (w / (nl * ls.pdf));
          L += c;
          if (terms) {
            ++diffuseVertices;  // this vertex, for the light it samples
            *term(false) += c;
            --diffuseVertices;
          }
        }
      }
    }

    // Continue the path by sampling the BSDF.
    if (!mat.isDelta()) ++diffuseVertices;
    else if (diffuseVertices > 0) deltaSinceDiffuse = true;
    BsdfSample bs;
    if (!bsdfSampleFrom(mat, wo, sampler, bs)) break;
    beta *= bs.weight;
    specularBounce = bs.delta;
    prevPdf = bs.pdf;
    prevPos = pos;
    prevNormal = sh.shadingNormal;
    if (bs.transmission) etaScale *= sqr(bs.eta);
    const Vec3 wiWorld = frame.toWorld(bs.wi);
    ray = spawnRay(pos, sh.positionError, sh.geomNormal, wiWorld);

    // Russian roulette on the throughput without the radiance scaling of refraction
    // (pbrt-v4, PathIntegrator::Li).
    const Vec3 rrBeta = beta * etaScale;
    if (depth >= m_rrDepth && maxComponent(rrBeta) < 1.0f) {
      const float q = std::max(0.0f, 1.0f - maxComponent(rrBeta));
      if (sampler.uniform() < q) break;
      beta /= 1.0f - q;
    }
  }
  return L;
}

}  // namespace voxcone

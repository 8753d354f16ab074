// Direct light by light sampling with shadow rays, and MIS weights against BSDF samples
// (direct_light.h).

#include "voxcone/integrator/direct_light.h"

#include "voxcone/accel/accel.h"
#include "voxcone/core/sampling.h"
#include "voxcone/scene/bsdf.h"

#include <cmath>

namespace voxcone {

namespace {
/// f cos L / pdf of light sample `ls` at `hit`, zero where a shadow ray finds it occluded. With
/// `bsdfSamples` > 0 the power heuristic's weight of a non-delta sample, one of `lightSamples`.
Vec3 shadeLightSample(const Scene& scene, const Accel& accel, const SurfaceHit& hit, const Vec3& woWorld,
                      const LightSample& ls, float minDistance = 0.0f, int lightSamples = 1, int bsdfSamples = 0) {
  if (!(ls.pdf > 0.0f)) return Vec3(0.0f);
  const Frame frame(hit.shadingNormal);
  const Vec3 wi = frame.toLocal(ls.wi);
  Material textured;
  const Material& mat = scene.materialAt(hit, textured);
  const Vec3 wo = frame.toLocal(woWorld);
  const Vec3 f = bsdfEval(mat, wo, wi) * std::fabs(wi.z);
  if (isBlack(f)) return Vec3(0.0f);
  if (accel.occluded(spawnRayTo(hit.position, hit.positionError, hit.geomNormal, ls.lightPos, ls.lightPosError, ls.lightNormal)))
    return Vec3(0.0f);
  Vec3 L = f * ls.radiance / ls.pdf;
  if (bsdfSamples > 0 && !ls.delta)
    L *= powerHeuristic(float(lightSamples) * ls.pdf, float(bsdfSamples) * bsdfPdf(mat, wo, wi));
  return ls.distance < minDistance ? L * sqr(ls.distance / minDistance) : L;
}
}  // namespace

Vec3 directLightSample(const Scene& scene, const Accel& accel, const SurfaceHit& hit, const Vec3& woWorld, const Vec2& u,
                       bool withEnvironment, float minDistance) {
  const LightSample ls = scene.sampleLight(hit.position, u, withEnvironment, &hit.shadingNormal, &hit.shadingNormal);
  return shadeLightSample(scene, accel, hit, woWorld, ls, minDistance);
}

Vec3 environmentLightSample(const Scene& scene, const Accel& accel, const SurfaceHit& hit, const Vec3& woWorld, const Vec2& u) {
  return shadeLightSample(scene, accel, hit, woWorld, scene.sampleEnvironment(hit.position, u, &hit.shadingNormal));
}

Vec3 estimateDirectLight(const Scene& scene, const Accel& accel, const SurfaceHit& hit, const Vec3& woWorld, Sampler& sampler,
                         int samples, bool withEnvironment, int bsdfSamples) {
  Vec3 sum(0.0f);
  for (int i = 0; i < samples; ++i) {
    // Under MIS the environment's samples must have the density escapedMis weighs them by: its
    // own sampler's, not the cosine mixture's.
    LightSample ls[LightTree::kMaxChoices];
    const int count = scene.sampleLights(hit.position, sampler.uniform2(), withEnvironment,
                                         bsdfSamples > 0 ? nullptr : &hit.shadingNormal, &hit.shadingNormal, ls);
    for (int k = 0; k < count; ++k) sum += shadeLightSample(scene, accel, hit, woWorld, ls[k], 0.0f, samples, bsdfSamples);
  }
  return sum / static_cast<float>(samples);
}

Vec3 misWeightedEmission(const Scene& scene, const SurfaceHit& hit, const Vec3& wi, float bsdfPdf, int bsdfSamples,
                         int lightSamples, const SurfaceHit* light) {
  const float pb = float(bsdfSamples) * bsdfPdf, nl = float(lightSamples);
  if (!light) return scene.escapedMis(wi, pb / nl);  // the heuristic is a ratio: (pb / nl) against one pdf
  const Vec3 Le = scene.emitted(*light, -wi);
  if (isBlack(Le)) return Vec3(0.0f);
  const float pl = scene.lightPdf(hit.position, &hit.shadingNormal, light->triangle, light->position, light->geomNormal);
  return Le * powerHeuristic(pb, nl * pl);
}

}  // namespace voxcone

#pragma once
// Whitted-style specular chains, shared by the whitted and voxcone integrators (private to
// src/integrator).

#include "voxcone/accel/accel.h"
#include "voxcone/core/sampler.h"
#include "voxcone/integrator/integrator.h"
#include "voxcone/scene/bsdf.h"
#include "voxcone/scene/scene.h"

namespace voxcone {

/// Radiance along `ray`: emission at every hit and the environment where it leaves the scene
/// (when `withEmission`), `shade(hit, wo, sampler,
/// depth, weight)` at the first non-delta surface (and the delta lobe of a smooth coat, which
/// `shade` leaves out, followed from there) (depth 0: the ray's own first hit; weight:
/// the product of the delta lobes' weights that led there), and at delta surfaces every lobe
/// followed (reflection and refraction both, for glass) up to `maxDepth` segments. With
/// `terms`, the emission seen is added to terms->emitted times its weight (and to terms->glint
/// after a delta bounce; shade records its own terms). Splitting at every dielectric doubles
/// the rays per level, so branches whose accumulated weight (`throughput`, the largest channel
/// of the product of lobe weights) falls below 1/1000 are dropped: they cannot change the pixel
/// visibly. From depth `splitDepth` on,
/// a surface with two lobes continues one of them instead, chosen with probability
/// proportional to its weight's largest channel and its weight divided by that probability
/// (unbiased; one sampler dimension per choice): a ray's cost then grows with its depth, not
/// exponentially. `metGlass`, when given, is set when a chain meets a transmissive surface.
template <typename Shade>
Vec3 traceDeltaChains(const Scene& scene, const Accel& accel, const Ray& ray, Sampler& sampler, int maxDepth,
                      int splitDepth, bool withEmission, const Shade& shade, RadianceTerms* terms = nullptr,
                      int depth = 0, float throughput = 1.0f, const Vec3& weight = Vec3(1.0f),
                      bool* metGlass = nullptr) {
  SurfaceHit sh;
  const bool hit = intersectSurface(scene, accel, ray, sh);
  const Vec3 woWorld = -glm::normalize(ray.dir);
  // Emission at the hit, or the environment where the ray leaves the scene.
  Vec3 L = !withEmission ? Vec3(0.0f) : hit ? scene.emitted(sh, woWorld) : scene.escaped(-woWorld);
  if (terms) {
    terms->emitted += weight * L;
    if (depth > 0) terms->glint += weight * L;
  }
  if (!hit) return L;
  Material textured;
  const Material& mat = scene.materialAt(sh, textured);
  if (!mat.isDelta()) {
    L += shade(sh, woWorld, sampler, depth, weight);
    // A smooth coat over a diffuse base (Plastic): shade took the base; the coat's reflection
    // is followed as a delta lobe below.
    if (!mat.hasDeltaLobe()) return L;
  } else if (metGlass && mat.isTransmissive()) {
    *metGlass = true;
  }
  if (depth + 1 >= maxDepth) return L;
  const Frame frame(sh.shadingNormal);
  DeltaLobe lobes[2];
  int n = bsdfDeltaLobes(mat, frame.toLocal(woWorld), lobes);
  if (n == 2 && depth >= splitDepth) {
    const float m0 = maxComponent(lobes[0].weight), m1 = maxComponent(lobes[1].weight);
    if (m0 + m1 > 0.0f) {
      const float p0 = m0 / (m0 + m1);
      const int pick = sampler.uniform() < p0 ? 0 : 1;
      const float p = pick == 0 ? p0 : 1.0f - p0;
      lobes[0] = lobes[pick];
      lobes[0].weight /= p;
      n = 1;
    }
  }
  for (int i = 0; i < n; ++i) {
    const float branch = throughput * maxComponent(lobes[i].weight);
    if (branch < 1e-3f) continue;
    const Ray next = spawnRay(sh.position, sh.positionError, sh.geomNormal, frame.toWorld(lobes[i].wi));
    L += lobes[i].weight * traceDeltaChains(scene, accel, next, sampler, maxDepth, splitDepth, withEmission, shade,
                                            terms, depth + 1, branch, weight * lobes[i].weight, metGlass);
  }
  return L;
}

}  // namespace voxcone

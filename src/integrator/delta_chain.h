#pragma once
// Whitted-style specular chains, shared by the whitted and voxcone integrators (private to
// src/integrator).

#include "voxcone/accel/accel.h"
#include "voxcone/core/sampler.h"
#include "voxcone/integrator/integrator.h"
#include "voxcone/scene/bsdf.h"
#include "voxcone/scene/scene.h"

namespace voxcone {

/// Radiance along `ray`: emission at every hit (when `withEmission`), `shade(hit, wo, sampler,
/// depth, weight)` at the first non-delta surface (depth 0: the ray's own first hit; weight:
/// the product of the delta lobes' weights that led there), and at delta surfaces every lobe
/// followed (reflection and refraction both, for glass) up to `maxDepth` segments. With
/// `terms`, the emission seen is added to terms->emitted times its weight (shade records its
/// own terms). Splitting at every dielectric doubles the rays per level, so branches whose
/// accumulated weight (`throughput`, the largest channel of the product of lobe weights) falls
/// below 1/1000 are dropped: they cannot change the pixel visibly.
template <typename Shade>
Vec3 traceDeltaChains(const Scene& scene, const Accel& accel, const Ray& ray, Sampler& sampler, int maxDepth,
                      bool withEmission, const Shade& shade, RadianceTerms* terms = nullptr, int depth = 0,
                      float throughput = 1.0f, const Vec3& weight = Vec3(1.0f)) {
  SurfaceHit sh;
  if (!intersectSurface(scene, accel, ray, sh)) return Vec3(0.0f);
  const Vec3 woWorld = -glm::normalize(ray.dir);
  Vec3 L = withEmission ? scene.emitted(sh, woWorld) : Vec3(0.0f);
  if (terms) terms->emitted += weight * L;
  const Material& mat = scene.materials[sh.material];
  if (!mat.isDelta()) return L + shade(sh, woWorld, sampler, depth, weight);
  if (depth + 1 >= maxDepth) return L;
  const Frame frame(sh.shadingNormal);
  DeltaLobe lobes[2];
  const int n = bsdfDeltaLobes(mat, frame.toLocal(woWorld), lobes);
  for (int i = 0; i < n; ++i) {
    const float branch = throughput * maxComponent(lobes[i].weight);
    if (branch < 1e-3f) continue;
    const Ray next = spawnRay(sh.position, sh.positionError, sh.geomNormal, frame.toWorld(lobes[i].wi));
    L += lobes[i].weight * traceDeltaChains(scene, accel, next, sampler, maxDepth, withEmission, shade, terms,
                                            depth + 1, branch, weight * lobes[i].weight);
  }
  return L;
}

}  // namespace voxcone

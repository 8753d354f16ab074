#pragma once
/// \file photon_mapping.h
/// Photon mapping after Jensen 2001, "Realistic Image Synthesis Using Photon Mapping",
/// ch. 7-9: the baseline the voxel-cone method is compared with.
///
/// Camera paths follow delta (specular) bounces exactly, adding emission seen directly or
/// through delta bounces. At the first non-delta hit the reflected radiance is split as in
/// Jensen's eq. 9.8:
///  - direct light by shadow rays (estimateDirectLight, one light sample);
///  - caustics (L S+ D) by a radiance estimate in the caustic map (eq. 7.6);
///  - indirect diffuse light: with final_gather = 0, a radiance estimate in the global map over
///    the photons that bounced at least once (photons straight from a light are direct light,
///    already counted by the shadow rays); with final_gather = N > 0, N cosine-distributed
///    gather rays, each taking the full radiance estimate (global map, direct photons included,
///    plus the caustic map) at its first diffuse hit (Jensen sec. 9.3.4).
/// Glossy (rough microfacet) surfaces store no photons (the tracer stores at diffuse hits
/// only), so they are handled as Jensen's "specular and glossy reflection" term: direct light
/// by shadow rays plus one BSDF-sampled continuation ray (Monte Carlo ray tracing); emission
/// found by that ray is not added (it is direct light, already sampled).
///
/// The radiance estimate is L = sum_p f(x, wp, wo) * Phi_p / (pi r^2) over the k nearest
/// photons within max_radius whose stored normal faces the same side as the viewer, where r is
/// the distance to the k-th photon (max_radius when fewer than k were found).
///
/// Options (all optional; unknown keys are SettingsErrors):
///  - `photons`, `caustic_photons`: photons emitted per pass (default RenderSettings.photons /
///    causticPhotons; the caustic pass is skipped when no material is delta: no L S+ D path
///    exists).
///  - `k`: photons per estimate, [1, 10000], default 100.
///  - `max_radius`: search radius, world units, > 0; default 5% of the radius of the scene's
///    bounding sphere (a bound that only matters where the map is sparse).
///  - `final_gather`: 0 (off) or the number of gather rays per shading point, default 0.
///  - `seed`: offset added to RenderSettings.seed for the photon pass, default 0.
///
/// Deterministic: prepare() traces photons deterministically and builds deterministic trees;
/// li() draws only from the pixel's random stream, so the image is the same at any thread count.

#include "voxcone/integrator/integrator.h"
#include "voxcone/photon/photon_kdtree.h"
#include "voxcone/photon/photon_tracer.h"

namespace voxcone {

/// Jensen-style photon mapping ("pm").
class PhotonMappingIntegrator final : public Integrator {
public:
  explicit PhotonMappingIntegrator(const IntegratorContext& context);
  std::string name() const override { return "pm"; }
  void prepare(Progress* progress) override;
  Vec3 li(const Ray& ray, Sampler& sampler) const override;
  nlohmann::json settingsJson() const override;
  nlohmann::json statsJson() const override;

private:
  /// Follow `ray` as a final-gather ray: reflected radiance at its first diffuse hit from the
  /// photon maps (global map in full plus caustics), after exact delta bounces and glossy
  /// continuations; no emission is added (it is direct light or a caustic at the gather origin).
  Vec3 gather(Ray ray, Sampler& sampler, int depth) const;
  /// Radiance estimate (Jensen eq. 7.6) at a diffuse surface point from `tree` over `photons`;
  /// `indirectOnly` skips photons with bounces == 0.
  Vec3 estimate(const PhotonKdTree& tree, const std::vector<Photon>& photons, bool indirectOnly,
                const SurfaceHit& hit, const Vec3& woWorld) const;

  const Scene& m_scene;
  const Accel& m_accel;
  int m_maxDepth;
  PhotonSettings m_photonSettings;
  int m_k = 100;
  float m_maxRadius = 0.0f;  ///< world units
  int m_finalGather = 0;

  PhotonMaps m_maps;
  PhotonKdTree m_globalTree, m_causticTree;
  double m_buildSeconds = 0.0;
};

}  // namespace voxcone

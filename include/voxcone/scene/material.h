#pragma once
/// \file material.h
/// Surface materials. A Material is plain data; bsdf.h evaluates and samples it.

#include "voxcone/core/math.h"

#include <array>
#include <string>

namespace voxcone {

/// The scattering model of a material.
enum class MaterialType {
  Lambertian,       ///< ideal diffuse, albedo
  OrenNayar,        ///< rough diffuse (Oren & Nayar 1994, qualitative model), albedo + sigma
  Mirror,           ///< perfect specular reflection, tinted by `specular`
  Dielectric,       ///< smooth glass: Fresnel reflection/refraction, total internal reflection
  Conductor,        ///< smooth metal with complex IOR (eta, k)
  RoughConductor,   ///< microfacet metal (Torrance-Sparrow, GGX/Beckmann, Smith G)
  RoughDielectric,  ///< microfacet glass (Walter et al. 2007)
  /// Coated diffuse (Mitsuba 3 `plastic`): a smooth dielectric coat of index `ior` (a delta
  /// reflection tinted by `specular`) over a Lambertian base of `albedo`, the light trapped
  /// between them summed in closed form (Weidlich & Wilkie 2007; Mitsuba's model).
  Plastic,
  /// Mitsuba 3 `roughplastic`: the coat a microfacet dielectric interface (GGX/Beckmann,
  /// `roughness`), its transmittance into the base integrated per cosine (CoatTable).
  RoughPlastic,
  /// A thin dielectric sheet (Mitsuba 3 `thindielectric`: a window pane): every internal
  /// reflection summed, the transmitted ray leaving undeflected.
  ThinDielectric,
};

/// Microfacet normal distribution.
enum class MicrofacetDistribution { GGX, Beckmann };

/// Which quantity a path carries: radiance (camera paths) or importance (light/photon paths).
/// Refraction scales radiance by 1/eta^2 but not importance (Veach 1997, sec. 5.2).
enum class TransportMode { Radiance, Importance };

/// What the coated models (Plastic, RoughPlastic) precompute from their coat: the coat's
/// transmittance into the base per cosine, and the base's internal diffuse reflectance at the
/// coat. Filled by prepareMaterial (bsdf.h), which Scene::finalize runs for every material.
struct CoatTable {
  static constexpr int kSize = 33;  ///< cos theta = i / 32, i = 0..32, linearly interpolated
  std::array<float, kSize> transmittance{};  ///< 1 - the coat's directional albedo (rough coats)
  float externalAlbedo = 0.0f;  ///< the coat's reflectance averaged over a cosine-weighted hemisphere, from outside
  float internalReflectance = -1.0f;  ///< the same seen from inside the coat (Fdr_int); < 0: not prepared
};

/// A named material. Units: reflectances in [0,1] per linear RGB channel; `emission` is
/// radiance in W/(sr m^2) (scene units cancel: only ratios matter).
/// A material's parameters, all but its name (so that a textured hit's copy, Scene::materialAt,
/// copies no string).
struct MaterialParams {
  MaterialType type = MaterialType::Lambertian;
  Vec3 albedo{0.5f};          ///< diffuse reflectance (Lambertian, OrenNayar); with a texture, its factor
  /// Index into Scene::textures of the diffuse reflectance's texture (times `albedo`), -1 none.
  int32_t albedoTexture = -1;
  float sigmaRad = 0.0f;      ///< Oren-Nayar: std. deviation of the facet angle, radians
  Vec3 specular{1.0f};        ///< tint of mirror, dielectric and conductor lobes
  float ior = 1.5f;           ///< dielectric: index inside / index outside (outside = +normal side)
  Vec3 eta{0.2f};             ///< conductor: real part of the complex IOR, per channel
  Vec3 k{3.0f};               ///< conductor: imaginary part (absorption), per channel
  float roughness = 0.1f;     ///< microfacet alpha (GGX alpha / Beckmann RMS slope), (0, 1]
  MicrofacetDistribution distribution = MicrofacetDistribution::GGX;
  /// Coated models: Mitsuba's `nonlinear` (the base's albedo darkened and saturated by the
  /// internal scattering: albedo / (1 - albedo Fdr_int) instead of albedo / (1 - Fdr_int)).
  bool coatNonlinear = false;
  CoatTable coat;             ///< coated models: prepareMaterial's precomputation
  Vec3 emission{0.0f};        ///< emitted radiance on the front (+geometric normal) side
  bool twoSidedEmission = false;
  /// Whether a non-transmissive material reflects on both sides (voxcone's default). When
  /// false it reflects only on the front side, as Mitsuba's BSDFs do outside `twosided`: no
  /// reflection when wo or wi lies below the shading normal, which SurfaceHit orients to the
  /// geometric normal's side (the same side for flat shading). Transmissive materials
  /// (dielectrics) ignore it: both sides are part of their model.
  bool twoSided = true;

  bool isEmissive() const { return !isBlack(emission); }
  /// True when every lobe is a Dirac delta (no BSDF evaluation, no light sampling).
  bool isDelta() const {
    return type == MaterialType::Mirror || type == MaterialType::Dielectric || type == MaterialType::Conductor ||
           type == MaterialType::ThinDielectric;
  }
  /// True when some lobe is a Dirac delta: the delta materials and a smooth plastic's coat
  /// (bsdfDeltaLobes lists them; bsdfSample returns them with BsdfSample::delta).
  bool hasDeltaLobe() const { return isDelta() || type == MaterialType::Plastic; }
  /// True when light can pass through the surface (the BSDF is not two-sided).
  bool isTransmissive() const {
    return type == MaterialType::Dielectric || type == MaterialType::RoughDielectric ||
           type == MaterialType::ThinDielectric;
  }
  /// True for the smooth transparent materials, which the voxel field leaves out (cones see
  /// through them).
  bool isClearGlass() const { return type == MaterialType::Dielectric || type == MaterialType::ThinDielectric; }
  /// True for the diffuse models (the voxel field stores their radiance).
  bool isDiffuse() const { return type == MaterialType::Lambertian || type == MaterialType::OrenNayar; }
  /// True for the coated diffuse models (Plastic, RoughPlastic).
  bool isCoated() const { return type == MaterialType::Plastic || type == MaterialType::RoughPlastic; }
  /// True when the material has a diffuse lobe: photons are stored on it and cones gather for it.
  bool hasDiffuseBase() const { return isDiffuse() || isCoated(); }
  /// True when the material scatters nothing seen from direction `cosFront` (the cosine of the
  /// direction with the shading normal, oriented as SurfaceHit's): a one-sided reflector from behind.
  bool blackFrom(float cosFront) const { return !twoSided && !isTransmissive() && !(cosFront > 0.0f); }
};

struct Material : MaterialParams {
  std::string name;
};

}  // namespace voxcone

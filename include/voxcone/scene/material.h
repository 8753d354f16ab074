#pragma once
/// \file material.h
/// Surface materials. A Material is plain data; bsdf.h evaluates and samples it.

#include "voxcone/core/math.h"

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
};

/// Microfacet normal distribution.
enum class MicrofacetDistribution { GGX, Beckmann };

/// Which quantity a path carries: radiance (camera paths) or importance (light/photon paths).
/// Refraction scales radiance by 1/eta^2 but not importance (Veach 1997, sec. 5.2).
enum class TransportMode { Radiance, Importance };

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
    return type == MaterialType::Mirror || type == MaterialType::Dielectric || type == MaterialType::Conductor;
  }
  /// True when light can pass through the surface (the BSDF is not two-sided).
  bool isTransmissive() const {
    return type == MaterialType::Dielectric || type == MaterialType::RoughDielectric;
  }
  /// True for the diffuse models (the voxel field stores their radiance).
  bool isDiffuse() const { return type == MaterialType::Lambertian || type == MaterialType::OrenNayar; }
  /// True when the material scatters nothing seen from direction `cosFront` (the cosine of the
  /// direction with the shading normal, oriented as SurfaceHit's): a one-sided reflector from behind.
  bool blackFrom(float cosFront) const { return !twoSided && !isTransmissive() && !(cosFront > 0.0f); }
};

struct Material : MaterialParams {
  std::string name;
};

}  // namespace voxcone

#pragma once
/// \file bsdf.h
/// Evaluation and importance sampling of every MaterialType.
///
/// Conventions (all functions): directions are unit vectors in the local shading frame, z is
/// the shading normal, both `wo` (towards the viewer / previous vertex) and `wi` (towards the
/// light / next vertex) point away from the surface.
/// - Non-transmissive materials are two-sided by default: if wo.z < 0 the lobe is mirrored to
///   the -z side (as if the normal were flipped); reflection needs wo.z * wi.z > 0. A material
///   with twoSided = false (Mitsuba's convention) scatters only when wo.z > 0 and wi.z > 0:
///   eval and pdf are 0, sample fails and no delta lobe exists otherwise.
/// - Transmissive materials: +z is the outside, `ior` is inside over outside; wo.z < 0 means
///   the path arrives from inside.
/// - Values returned by bsdfEval are f(wo, wi) WITHOUT the cosine factor.

#include "voxcone/core/math.h"
#include "voxcone/scene/material.h"

namespace voxcone {

/// One sampled direction.
struct BsdfSample {
  Vec3 wi{0.0f};        ///< sampled direction (local frame)
  Vec3 weight{0.0f};    ///< f * |cos(wi)| / pdf (for delta lobes: the lobe's weight)
  float pdf = 0.0f;     ///< solid-angle density; for delta lobes the discrete probability of the lobe
  bool delta = false;   ///< true when sampled from a Dirac lobe
  bool transmission = false;
  float eta = 1.0f;     ///< relative IOR crossed (1 for reflection); for Russian roulette scaling
};

/// f(wo, wi) (no cosine). Zero for delta materials.
Vec3 bsdfEval(const Material& m, const Vec3& wo, const Vec3& wi, TransportMode mode = TransportMode::Radiance);

/// Solid-angle pdf of bsdfSample producing wi from wo. Zero for delta materials.
float bsdfPdf(const Material& m, const Vec3& wo, const Vec3& wi);

/// Sample wi given wo with uc, u uniform in [0,1). Returns false when no direction results
/// (e.g. wo grazing, sample below the horizon).
bool bsdfSample(const Material& m, const Vec3& wo, float uc, const Vec2& u, BsdfSample& out,
                TransportMode mode = TransportMode::Radiance);

/// bsdfSample with uc, then u, drawn from `gen` (a Sampler or an Rng: anything with uniform()
/// and uniform2(); the order every caller keeps, so images stay the same); false also when the
/// sample carries no weight.
template <typename Generator>
bool bsdfSampleFrom(const Material& m, const Vec3& wo, Generator& gen, BsdfSample& out,
                    TransportMode mode = TransportMode::Radiance) {
  const float uc = gen.uniform();
  const Vec2 u = gen.uniform2();
  return bsdfSample(m, wo, uc, u, out, mode) && !isBlack(out.weight);
}

/// A deterministic lobe of a delta material (for Whitted-style splitting).
struct DeltaLobe {
  Vec3 wi{0.0f};
  Vec3 weight{0.0f};  ///< f * |cos| / delta: the factor the incoming radiance is multiplied by
  bool transmission = false;
};

/// Enumerate the delta lobes of `m` for wo: mirror and conductor give one reflection; a
/// dielectric gives reflection (weight F) and refraction (weight 1-F, /eta^2 for radiance),
/// or only reflection under total internal reflection. Returns the number written (<= 2).
int bsdfDeltaLobes(const Material& m, const Vec3& wo, DeltaLobe out[2], TransportMode mode = TransportMode::Radiance);

/// Unpolarized Fresnel reflectance of a dielectric interface; cosThetaI in [-1,1] (negative =
/// arriving from inside), eta = inside/outside. 1 under total internal reflection.
float fresnelDielectric(float cosThetaI, float eta);

/// Unpolarized Fresnel reflectance of a conductor with complex IOR eta + i k, per channel.
Vec3 fresnelConductor(float cosThetaI, const Vec3& eta, const Vec3& k);

/// Fill what a material's model precomputes (the coat tables of Plastic and RoughPlastic;
/// nothing for the others). Scene::finalize runs it for every material; a coated material that
/// skipped it evaluates as black.
void prepareMaterial(MaterialParams& m);

/// The diffuse lobe alone, f(wo, wi) without the cosine: the whole BSDF of the diffuse models,
/// a coated model's base under its coat (Plastic's delta coat and RoughPlastic's glossy coat
/// left out), 0 for the others. Cones gather for this lobe; the coat is gathered apart.
Vec3 bsdfEvalBase(const Material& m, const Vec3& wo, const Vec3& wi);

/// Sample a coated model's coat alone (RoughPlastic: its microfacet reflection, by visible
/// normals; Plastic: its delta reflection): weight = f_coat |cos| / pdf_coat. False for other
/// materials and where the coat sends nothing.
bool coatSample(const Material& m, const Vec3& wo, const Vec2& u, BsdfSample& out);

/// The diffuse reflectance light leaves with, for the photons' field (view-independent): the
/// albedo for the diffuse models; for the coated ones the base's reflectance through the coat,
/// averaged over cosine-weighted directions in and out; 0 otherwise.
Vec3 diffuseReflectance(const Material& m);

}  // namespace voxcone

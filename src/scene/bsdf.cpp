/// \file bsdf.cpp
/// Evaluation and sampling of every MaterialType (conventions in bsdf.h).
///
/// Microfacet models use the height-correlated Smith masking-shadowing function (Heitz 2014,
/// sec. 6) for both reflection and transmission, and sample the distribution of visible normals
/// of wo, so that every sampled weight is G2 / G1(wo) times the Fresnel term and tint (<= 1).

#include "voxcone/scene/bsdf.h"

#include "microfacet.h"
#include "voxcone/core/sampling.h"

namespace voxcone {
namespace {

/// Roughness floor. Below it D exceeds ~1e7 and float round-off in the half vector dominates;
/// such surfaces should be authored as smooth (delta) materials.
constexpr float kMinAlpha = 1e-3f;

float alphaOf(const Material& m) { return std::max(kMinAlpha, m.roughness); }

/// Mirror direction of w about the unit normal n.
Vec3 reflect(const Vec3& w, const Vec3& n) { return -w + 2.0f * glm::dot(w, n) * n; }

/// Refraction of wi through the interface with unit normal n (pbrt-v4 Refract); eta is the index
/// on the -n side over the index on the +n side, and is inverted (n flipped) when wi.n < 0.
/// Returns false under total internal reflection; etap receives the relative IOR crossed
/// (index of the transmitted side over the incident side).
bool refract(const Vec3& wi, Vec3 n, float eta, float& etap, Vec3& wt) {
  float cosI = glm::dot(n, wi);
  if (cosI < 0.0f) {
    eta = 1.0f / eta;
    cosI = -cosI;
    n = -n;
  }
  const float sin2I = std::max(0.0f, 1.0f - cosI * cosI);
  const float sin2T = sin2I / (eta * eta);
  if (sin2T >= 1.0f) return false;
  const float cosT = safeSqrt(1.0f - sin2T);
  wt = -wi / eta + (cosI / eta - cosT) * n;
  etap = eta;
  return true;
}

/// Flip a two-sided material's directions so that wo lies in the upper hemisphere.
Vec3 upper(const Vec3& w, bool flip) { return flip ? Vec3(w.x, w.y, -w.z) : w; }

bool validDir(const Vec3& w) { return std::isfinite(w.x) && std::isfinite(w.y) && std::isfinite(w.z) && w.z != 0.0f; }

// ---------------------------------------------------------------------------------------------
// Oren-Nayar

/// Qualitative Oren-Nayar model (Oren & Nayar 1994, sec. 4.4; as pbrt-v3 OrenNayar) for wo, wi
/// in the upper hemisphere: albedo/pi (A + B max(0, cos(phi_i - phi_o)) sin(alpha) tan(beta)).
Vec3 orenNayar(const Material& m, const Vec3& wo, const Vec3& wi) {
  const float s2 = m.sigmaRad * m.sigmaRad;
  const float a = 1.0f - s2 / (2.0f * (s2 + 0.33f));
  const float b = 0.45f * s2 / (s2 + 0.09f);
  const float sinO = std::sqrt(wo.x * wo.x + wo.y * wo.y);
  const float sinI = std::sqrt(wi.x * wi.x + wi.y * wi.y);
  // cos(phi_i - phi_o); the azimuth is undefined (and the term irrelevant) at the pole. The 1e-4
  // threshold is pbrt-v3's.
  float maxCos = 0.0f;
  if (sinI > 1e-4f && sinO > 1e-4f) maxCos = std::max(0.0f, (wo.x * wi.x + wo.y * wi.y) / (sinI * sinO));
  // alpha = max(theta_i, theta_o), beta = min(theta_i, theta_o).
  float sinAlpha, tanBeta;
  if (wi.z > wo.z) {
    sinAlpha = sinO;
    tanBeta = sinI / wi.z;
  } else {
    sinAlpha = sinI;
    tanBeta = sinO / wo.z;
  }
  return m.albedo * kInvPi * (a + b * maxCos * sinAlpha * tanBeta);
}

// ---------------------------------------------------------------------------------------------
// Rough dielectric (Walter et al. 2007), after pbrt-v4 DielectricBxDF.

/// Generalized half vector (Walter 2007, eq. 16) of a pair that passes the checks of pbrt-v4:
/// facing +z, wo and wi each on the same side of wm as of the macro surface. Returns false
/// for degenerate or back-facing configurations.
bool roughDielectricHalf(const Material& m, const Vec3& wo, const Vec3& wi, bool& reflect, float& etap, Vec3& wm) {
  if (!validDir(wo) || !validDir(wi)) return false;
  reflect = wo.z * wi.z > 0.0f;
  etap = 1.0f;
  if (!reflect) etap = wo.z > 0.0f ? m.ior : 1.0f / m.ior;
  wm = wi * etap + wo;
  const float len2 = glm::dot(wm, wm);
  if (!(len2 > 0.0f)) return false;
  wm /= std::sqrt(len2);
  if (wm.z < 0.0f) wm = -wm;
  // Back-facing microfacets (Walter 2007, chi+ terms of eqs. 20-21).
  if (glm::dot(wm, wi) * wi.z < 0.0f || glm::dot(wm, wo) * wo.z < 0.0f) return false;
  return true;
}

/// Fresnel transmittance 1 - F of a refracted pair with both cosines known (|cos| on the incident
/// and on the transmitted side, etap = n_t / n_i): T = 1 - (r_s^2 + r_p^2) / 2 with 1 - r^2 =
/// 4ab / (a + b)^2. Symmetric under swapping the sides, and accurate near total internal
/// reflection where 1 - fresnelDielectric loses every digit to cancellation.
float fresnelTransmittancePair(float cosI, float cosT, float etap) {
  const float s = cosI + etap * cosT, p = etap * cosI + cosT;
  if (!(s > 0.0f) || !(p > 0.0f)) return 0.0f;
  return std::min(1.0f, 2.0f * etap * cosI * cosT * (1.0f / (s * s) + 1.0f / (p * p)));
}

Vec3 roughDielectricEval(const Material& m, const Vec3& wo, const Vec3& wi, TransportMode mode) {
  bool refl;
  float etap;
  Vec3 wm;
  if (!roughDielectricHalf(m, wo, wi, refl, etap, wm)) return Vec3(0.0f);
  const MicrofacetDistribution dist = m.distribution;
  const float alpha = alphaOf(m);
  const float dotO = glm::dot(wo, wm), dotI = glm::dot(wi, wm);
  const float d = microfacet::distributionD(dist, alpha, wm);
  const float g = microfacet::g2(dist, alpha, wo, wi, !refl);
  if (refl) {
    // Walter 2007, eq. 20.
    const float fr = fresnelDielectric(dotO, m.ior);
    return m.specular * (d * g * fr / std::fabs(4.0f * wi.z * wo.z));
  }
  // Walter 2007, eq. 21 with eta_o = 1 (relative IOR etap on the wi side).
  const float denom = sqr(dotI + dotO / etap) * wi.z * wo.z;
  if (denom == 0.0f) return Vec3(0.0f);
  const float t = fresnelTransmittancePair(std::fabs(dotO), std::fabs(dotI), etap);
  float ft = d * t * g * std::fabs(dotI * dotO / denom);
  // Radiance is compressed into the smaller solid angle of the denser side (Veach 1997, 5.2).
  if (mode == TransportMode::Radiance) ft /= sqr(etap);
  return m.specular * ft;
}

float roughDielectricPdf(const Material& m, const Vec3& wo, const Vec3& wi) {
  bool refl;
  float etap;
  Vec3 wm;
  if (!roughDielectricHalf(m, wo, wi, refl, etap, wm)) return 0.0f;
  const float alpha = alphaOf(m);
  const float dotO = glm::dot(wo, wm), dotI = glm::dot(wi, wm);
  const float pdfWm = microfacet::visibleNormalPdf(m.distribution, alpha, wo, wm);
  if (refl) {
    // Jacobian of the reflection map dwm/dwi = 1 / (4 |wo.wm|) (Walter 2007, eq. 14); the
    // reflection lobe is chosen with probability F.
    return pdfWm / (4.0f * std::fabs(dotO)) * fresnelDielectric(dotO, m.ior);
  }
  // Jacobian of refraction dwm/dwi = |wi.wm| / (wi.wm + wo.wm / etap)^2 (Walter 2007, eq. 17);
  // the transmission lobe is chosen with probability 1 - F(wo.wm), here the better-conditioned
  // but equal T of the evaluation, so that weights and densities agree near total reflection.
  const float denom = sqr(dotI + dotO / etap);
  if (denom == 0.0f) return 0.0f;
  return pdfWm * std::fabs(dotI) / denom * fresnelTransmittancePair(std::fabs(dotO), std::fabs(dotI), etap);
}

bool roughDielectricSample(const Material& m, const Vec3& wo, float uc, const Vec2& u, BsdfSample& out,
                           TransportMode mode) {
  const MicrofacetDistribution dist = m.distribution;
  const float alpha = alphaOf(m);
  // Visible normal of wo seen from its own side (wm always faces +z).
  const Vec3 wm = microfacet::sampleVisibleNormal(dist, alpha, wo.z < 0.0f ? -wo : wo, u);
  const float dotO = glm::dot(wo, wm);
  if (dotO == 0.0f) return false;
  const float fr = fresnelDielectric(dotO, m.ior);
  Vec3 wi;
  bool transmission;
  float etap = 1.0f;
  if (uc < fr) {
    wi = reflect(wo, wm);
    if (!(wi.z * wo.z > 0.0f)) return false;
    transmission = false;
  } else {
    if (!refract(wo, wm, m.ior, etap, wi)) return false;
    if (!(wi.z * wo.z < 0.0f)) return false;
    transmission = true;
  }
  const float pdf = roughDielectricPdf(m, wo, wi);
  if (!(pdf > 0.0f)) return false;
  // f |cos_i| / pdf collapses to G2 / G1(wo) once D, Fresnel and the Jacobians cancel
  // (the visible-normal estimator of Heitz 2018, sec. 2; likewise for transmission).
  float w = microfacet::g2(dist, alpha, wo, wi, transmission) / microfacet::g1(dist, alpha, wo);
  if (transmission && mode == TransportMode::Radiance) w /= sqr(etap);
  out.wi = wi;
  out.weight = m.specular * w;
  out.pdf = pdf;
  out.delta = false;
  out.transmission = transmission;
  out.eta = transmission ? etap : 1.0f;
  return isFinite(out.weight);
}

// ---------------------------------------------------------------------------------------------
// Rough conductor (Torrance-Sparrow with visible-normal sampling). wo, wi in the upper hemisphere.

/// Torrance & Sparrow 1967 / Walter 2007, eq. 20: specular F(wo.wm) D G / (4 cos_o cos_i), the
/// Fresnel term from `fresnel` (cosine -> reflectance per channel).
template <typename Fresnel>
Vec3 microfacetReflection(const Material& m, const Vec3& wo, const Vec3& wi, const Fresnel& fresnel) {
  Vec3 wm = wo + wi;
  const float len2 = glm::dot(wm, wm);
  if (!(len2 > 0.0f)) return Vec3(0.0f);
  wm /= std::sqrt(len2);
  const float alpha = alphaOf(m);
  const float d = microfacet::distributionD(m.distribution, alpha, wm);
  const float g = microfacet::g2(m.distribution, alpha, wo, wi, false);
  const Vec3 f = fresnel(glm::dot(wo, wm));
  return m.specular * f * (d * g / (4.0f * wo.z * wi.z));
}

Vec3 roughConductorEval(const Material& m, const Vec3& wo, const Vec3& wi) {
  return microfacetReflection(m, wo, wi, [&](float c) { return fresnelConductor(c, m.eta, m.k); });
}

float roughConductorPdf(const Material& m, const Vec3& wo, const Vec3& wi) {
  Vec3 wm = wo + wi;
  const float len2 = glm::dot(wm, wm);
  if (!(len2 > 0.0f)) return 0.0f;
  wm /= std::sqrt(len2);
  const float dotO = glm::dot(wo, wm);
  if (!(dotO > 0.0f)) return 0.0f;
  // Visible-normal density times the reflection Jacobian 1 / (4 wo.wm).
  return microfacet::visibleNormalPdf(m.distribution, alphaOf(m), wo, wm) / (4.0f * dotO);
}

// ---------------------------------------------------------------------------------------------
// Coated diffuse (Mitsuba 3 plastic / roughplastic). wo, wi in the upper hemisphere.
//
// Light refracts through the coat (transmittance T(cos)), scatters at the Lambertian base,
// and leaves through the coat; what the coat reflects back in is scattered again, a geometric
// series summed in closed form: base = albedo / (1 - Fdr_int) (or albedo / (1 - albedo Fdr_int)
// when nonlinear), over eta^2 for the radiance compressed inside (Weidlich & Wilkie 2007;
// Mitsuba's plastic and roughplastic):
//   f_base(wo, wi) = base / (pi eta^2) T(cos_o) T(cos_i).

float coatTransmittance(const Material& m, float cosTheta) {
  const float c = std::clamp(cosTheta, 0.0f, 1.0f);
  if (m.type == MaterialType::Plastic) return 1.0f - fresnelDielectric(c, m.ior);
  const float x = c * float(CoatTable::kSize - 1);
  const int i = std::min(int(x), CoatTable::kSize - 2);
  const float t = x - float(i);
  return (1.0f - t) * m.coat.transmittance[i] + t * m.coat.transmittance[i + 1];
}

Vec3 coatedBase(const Material& m) {
  const float ri = m.coat.internalReflectance;
  const Vec3 denom = m.coatNonlinear ? Vec3(1.0f) - m.albedo * ri : Vec3(1.0f - ri);
  return m.albedo / (denom * sqr(m.ior));
}

Vec3 coatedBaseEval(const Material& m, const Vec3& wo, const Vec3& wi) {
  if (!(m.coat.internalReflectance >= 0.0f)) return Vec3(0.0f);
  return coatedBase(m) * (kInvPi * coatTransmittance(m, wo.z) * coatTransmittance(m, wi.z));
}

Vec3 roughCoatEval(const Material& m, const Vec3& wo, const Vec3& wi) {
  return microfacetReflection(m, wo, wi, [&](float c) { return Vec3(fresnelDielectric(c, m.ior)); });
}

/// The probability of sampling the coat for wo: its reflectance (F, or 1 - T for a rough coat)
/// times the specular tint's share of tint + albedo (Mitsuba's specular sampling weight), over
/// that plus the base's share times T.
float coatProbability(const Material& m, float cosO) {
  const float s = luminance(m.specular), a = luminance(m.albedo);
  const float sw = s + a > 0.0f ? s / (s + a) : 0.5f;
  const float r = 1.0f - coatTransmittance(m, cosO);
  const float ps = r * sw, pd = (1.0f - r) * (1.0f - sw);
  return ps + pd > 0.0f ? ps / (ps + pd) : 0.5f;
}

Vec3 coatedEval(const Material& m, const Vec3& wo, const Vec3& wi) {
  Vec3 f = coatedBaseEval(m, wo, wi);
  if (m.type == MaterialType::RoughPlastic) f += roughCoatEval(m, wo, wi);
  return f;
}

float coatedPdf(const Material& m, const Vec3& wo, const Vec3& wi) {
  const float ps = coatProbability(m, wo.z);
  float pdf = (1.0f - ps) * cosineHemispherePdf(wi.z);
  if (m.type == MaterialType::RoughPlastic) pdf += ps * roughConductorPdf(m, wo, wi);
  return pdf;
}

/// The coat's directional albedo for a direction at cos theta = mu from the side where the
/// Fresnel term is fresnelDielectric(+/-cos, ior) (`inside`: from within the coat): the
/// visible-normal estimator F G2 / G1 (Heitz 2018) on an n x n stratified grid.
double roughCoatAlbedo(const Material& m, double mu, bool inside) {
  constexpr int n = 32;
  const Vec3 wo(float(std::sqrt(std::max(0.0, 1.0 - mu * mu))), 0.0f, float(mu));
  const float alpha = alphaOf(m);
  double sum = 0.0;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) {
      const Vec2 u((float(i) + 0.5f) / float(n), (float(j) + 0.5f) / float(n));
      const Vec3 wm = microfacet::sampleVisibleNormal(m.distribution, alpha, wo, u);
      const Vec3 wi = reflect(wo, wm);
      if (!(wi.z > 0.0f)) continue;
      const float c = glm::dot(wo, wm);
      const float fr = fresnelDielectric(inside ? -c : c, m.ior);
      sum += double(fr) * microfacet::g2(m.distribution, alpha, wo, wi, false) / microfacet::g1(m.distribution, alpha, wo);
    }
  return sum / double(n * n);
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Coated diffuse: precomputation and the lobes apart

void prepareMaterial(MaterialParams& params) {
  if (params.type != MaterialType::Plastic && params.type != MaterialType::RoughPlastic) return;
  Material m;
  static_cast<MaterialParams&>(m) = params;
  const bool rough = m.type == MaterialType::RoughPlastic;
  // The coat's reflectance at cos theta = mu, from outside or from inside (total internal
  // reflection included), and its cosine-weighted hemispherical average 2 int R(mu) mu dmu by
  // the midpoint rule (TIR's kink inside makes a coarse rule visibly wrong).
  const auto reflectance = [&](double mu, bool inside) {
    return rough ? roughCoatAlbedo(m, mu, inside) : double(fresnelDielectric(float(inside ? -mu : mu), m.ior));
  };
  const auto average = [&](bool inside) {
    const int n = rough ? 256 : 4096;
    double sum = 0.0;
    for (int i = 0; i < n; ++i) {
      const double mu = (i + 0.5) / n;
      sum += reflectance(mu, inside) * mu;
    }
    return 2.0 * sum / n;
  };
  CoatTable& table = params.coat;
  for (int i = 0; i < CoatTable::kSize; ++i) {
    const double mu = std::max(1e-4, double(i) / double(CoatTable::kSize - 1));
    table.transmittance[i] = float(1.0 - reflectance(mu, false));
  }
  table.externalAlbedo = float(average(false));
  table.internalReflectance = float(average(true));
}

Vec3 bsdfEvalBase(const Material& m, const Vec3& wo, const Vec3& wi) {
  if (m.isDiffuse()) return bsdfEval(m, wo, wi);
  if (!m.isCoated() || !validDir(wo) || !validDir(wi) || !(wo.z * wi.z > 0.0f)) return Vec3(0.0f);
  if (m.blackFrom(wo.z) || m.blackFrom(wi.z)) return Vec3(0.0f);
  const bool flip = wo.z < 0.0f;
  const Vec3 f = coatedBaseEval(m, upper(wo, flip), upper(wi, flip));
  return isFinite(f) ? f : Vec3(0.0f);
}

bool coatSample(const Material& m, const Vec3& wo, const Vec2& u, BsdfSample& out) {
  out = BsdfSample{};
  if (!m.isCoated() || !validDir(wo) || m.blackFrom(wo.z)) return false;
  const bool flip = wo.z < 0.0f;
  const Vec3 o = upper(wo, flip);
  if (m.type == MaterialType::Plastic) {
    out.wi = upper(Vec3(-o.x, -o.y, o.z), flip);
    out.pdf = 1.0f;
    out.delta = true;
    out.weight = m.specular * fresnelDielectric(o.z, m.ior);
  } else {
    const float alpha = alphaOf(m);
    const Vec3 wm = microfacet::sampleVisibleNormal(m.distribution, alpha, o, u);
    const Vec3 i = reflect(o, wm);
    if (!(i.z > 0.0f)) return false;
    out.pdf = roughConductorPdf(m, o, i);
    out.wi = upper(i, flip);
    out.weight = m.specular * fresnelDielectric(glm::dot(o, wm), m.ior) *
                 (microfacet::g2(m.distribution, alpha, o, i, false) / microfacet::g1(m.distribution, alpha, o));
  }
  if (!isFinite(out.weight) || !(out.pdf > 0.0f) || !validDir(out.wi) || isBlack(out.weight)) {
    out = BsdfSample{};
    return false;
  }
  return true;
}

Vec3 diffuseReflectance(const Material& m) {
  if (m.isDiffuse()) return m.albedo;
  if (!m.isCoated() || !(m.coat.internalReflectance >= 0.0f)) return Vec3(0.0f);
  // f_base integrated: base / eta^2 T(cos_o) (1 - R_ext); T(cos_o) averaged the same way.
  return coatedBase(m) * sqr(1.0f - m.coat.externalAlbedo);
}

// ---------------------------------------------------------------------------------------------
// Fresnel

float fresnelDielectric(float cosThetaI, float eta) {
  // pbrt-v4 FrDielectric: the exact unpolarized Fresnel reflectance (Born & Wolf, sec. 1.5).
  if (!std::isfinite(cosThetaI) || !(eta > 0.0f)) return 1.0f;
  cosThetaI = std::clamp(cosThetaI, -1.0f, 1.0f);
  if (cosThetaI < 0.0f) {
    eta = 1.0f / eta;
    cosThetaI = -cosThetaI;
  }
  const float sin2I = 1.0f - cosThetaI * cosThetaI;
  const float sin2T = sin2I / (eta * eta);
  if (sin2T >= 1.0f) return 1.0f;
  const float cosT = safeSqrt(1.0f - sin2T);
  const float rParl = (eta * cosThetaI - cosT) / (eta * cosThetaI + cosT);
  const float rPerp = (cosThetaI - eta * cosT) / (cosThetaI + eta * cosT);
  return 0.5f * (rParl * rParl + rPerp * rPerp);
}

Vec3 fresnelConductor(float cosThetaI, const Vec3& eta, const Vec3& k) {
  // Exact unpolarized reflectance for the complex relative index eta + i k (pbrt-v4 FrComplex),
  // in the closed real form of pbrt-v3 FrConductor (after Born & Wolf, ch. 14): identical
  // values without complex division, in double to keep the cancellations harmless.
  const double c = std::isfinite(cosThetaI) ? std::clamp(double(std::fabs(cosThetaI)), 0.0, 1.0) : 1.0;
  const double cos2 = c * c, sin2 = 1.0 - cos2;
  Vec3 r;
  for (int ch = 0; ch < 3; ++ch) {
    const double e2 = double(eta[ch]) * eta[ch], k2 = double(k[ch]) * k[ch];
    const double t0 = e2 - k2 - sin2;
    const double a2b2 = std::sqrt(t0 * t0 + 4.0 * e2 * k2);  // |n^2 - sin^2|
    const double a = std::sqrt(std::max(0.0, 0.5 * (a2b2 + t0)));
    const double t1 = a2b2 + cos2, t2 = 2.0 * c * a;
    const double t3 = cos2 * a2b2 + sin2 * sin2, t4 = t2 * sin2;
    if (!(t1 + t2 > 0.0) || !(t3 + t4 > 0.0)) {
      r[ch] = 1.0f;  // grazing on a degenerate index (eta = k = 0): everything is reflected
      continue;
    }
    const double rs = (t1 - t2) / (t1 + t2);
    const double rp = rs * (t3 - t4) / (t3 + t4);
    r[ch] = static_cast<float>(std::clamp(0.5 * (rs + rp), 0.0, 1.0));
  }
  return r;
}

// ---------------------------------------------------------------------------------------------
// Public interface

Vec3 bsdfEval(const Material& m, const Vec3& wo, const Vec3& wi, TransportMode mode) {
  if (!validDir(wo) || !validDir(wi)) return Vec3(0.0f);
  // One-sided reflectors (Mitsuba's BSDFs without `twosided`): nothing below the normal.
  if (m.blackFrom(wo.z) || m.blackFrom(wi.z)) return Vec3(0.0f);
  Vec3 f(0.0f);
  switch (m.type) {
    case MaterialType::Mirror:
    case MaterialType::Dielectric:
    case MaterialType::ThinDielectric:
    case MaterialType::Conductor: return Vec3(0.0f);
    case MaterialType::RoughDielectric: f = roughDielectricEval(m, wo, wi, mode); break;
    case MaterialType::Lambertian:
    case MaterialType::OrenNayar:
    case MaterialType::RoughConductor:
    case MaterialType::Plastic:
    case MaterialType::RoughPlastic: {
      if (!(wo.z * wi.z > 0.0f)) return Vec3(0.0f);
      const bool flip = wo.z < 0.0f;
      const Vec3 o = upper(wo, flip), i = upper(wi, flip);
      if (m.type == MaterialType::Lambertian) f = m.albedo * kInvPi;
      else if (m.type == MaterialType::OrenNayar) f = orenNayar(m, o, i);
      else if (m.isCoated()) f = coatedEval(m, o, i);
      else f = roughConductorEval(m, o, i);
      break;
    }
  }
  return isFinite(f) ? f : Vec3(0.0f);
}

float bsdfPdf(const Material& m, const Vec3& wo, const Vec3& wi) {
  if (!validDir(wo) || !validDir(wi)) return 0.0f;
  if (m.blackFrom(wo.z) || m.blackFrom(wi.z)) return 0.0f;
  float pdf = 0.0f;
  switch (m.type) {
    case MaterialType::Mirror:
    case MaterialType::Dielectric:
    case MaterialType::ThinDielectric:
    case MaterialType::Conductor: return 0.0f;
    case MaterialType::RoughDielectric: pdf = roughDielectricPdf(m, wo, wi); break;
    case MaterialType::Lambertian:
    case MaterialType::OrenNayar:
    case MaterialType::RoughConductor:
    case MaterialType::Plastic:
    case MaterialType::RoughPlastic: {
      if (!(wo.z * wi.z > 0.0f)) return 0.0f;
      const bool flip = wo.z < 0.0f;
      const Vec3 o = upper(wo, flip), i = upper(wi, flip);
      pdf = m.type == MaterialType::RoughConductor ? roughConductorPdf(m, o, i)
            : m.isCoated()                         ? coatedPdf(m, o, i)
                                                   : cosineHemispherePdf(i.z);
      break;
    }
  }
  return std::isfinite(pdf) ? pdf : 0.0f;
}

bool bsdfSample(const Material& m, const Vec3& wo, float uc, const Vec2& u, BsdfSample& out, TransportMode mode) {
  out = BsdfSample{};
  if (!validDir(wo) || m.blackFrom(wo.z)) return false;
  const bool flip = wo.z < 0.0f;
  switch (m.type) {
    case MaterialType::Lambertian:
    case MaterialType::OrenNayar: {
      const Vec3 i = sampleCosineHemisphere(u);
      if (!(i.z > 0.0f)) return false;
      const Vec3 o = upper(wo, flip);
      out.wi = upper(i, flip);
      out.pdf = cosineHemispherePdf(i.z);
      // f cos / pdf = f pi: the albedo for Lambertian.
      out.weight = m.type == MaterialType::Lambertian ? m.albedo : orenNayar(m, o, i) * kPi;
      break;
    }
    case MaterialType::Mirror:
    case MaterialType::Conductor: {
      out.wi = Vec3(-wo.x, -wo.y, wo.z);
      out.pdf = 1.0f;
      out.delta = true;
      out.weight = m.type == MaterialType::Mirror ? m.specular : m.specular * fresnelConductor(wo.z, m.eta, m.k);
      break;
    }
    case MaterialType::Dielectric: {
      const float fr = fresnelDielectric(wo.z, m.ior);
      out.delta = true;
      if (uc < fr) {
        // Reflection chosen with probability F: weight F / F = 1.
        out.wi = Vec3(-wo.x, -wo.y, wo.z);
        out.pdf = fr;
        out.weight = m.specular;
      } else {
        float etap;
        Vec3 wt;
        if (!refract(wo, Vec3(0.0f, 0.0f, 1.0f), m.ior, etap, wt) || wt.z == 0.0f) return false;
        out.wi = wt;
        out.pdf = 1.0f - fr;
        out.weight = mode == TransportMode::Radiance ? m.specular / sqr(etap) : m.specular;
        out.transmission = true;
        out.eta = etap;
      }
      break;
    }
    case MaterialType::RoughConductor: {
      const Vec3 o = upper(wo, flip);
      const MicrofacetDistribution dist = m.distribution;
      const float alpha = alphaOf(m);
      const Vec3 wm = microfacet::sampleVisibleNormal(dist, alpha, o, u);
      const Vec3 i = reflect(o, wm);
      if (!(i.z > 0.0f)) return false;
      out.pdf = roughConductorPdf(m, o, i);
      if (!(out.pdf > 0.0f)) return false;
      out.wi = upper(i, flip);
      // f cos_i / pdf = F G2 / G1(wo) (the visible-normal estimator of Heitz 2018, sec. 2).
      out.weight = m.specular * fresnelConductor(glm::dot(o, wm), m.eta, m.k) *
                   (microfacet::g2(dist, alpha, o, i, false) / microfacet::g1(dist, alpha, o));
      break;
    }
    case MaterialType::ThinDielectric: {
      // Both faces' reflections and every internal bounce summed (no absorption): R' = R + T^2 R
      // / (1 - R^2) = 2R / (1 + R); the rest passes straight through.
      const float r = fresnelDielectric(std::fabs(wo.z), m.ior);
      const float rt = r < 1.0f ? 2.0f * r / (1.0f + r) : 1.0f;
      out.delta = true;
      out.weight = m.specular;
      if (uc < rt) {
        out.wi = Vec3(-wo.x, -wo.y, wo.z);
        out.pdf = rt;
      } else {
        out.wi = -wo;
        out.pdf = 1.0f - rt;
        out.transmission = true;
      }
      break;
    }
    case MaterialType::Plastic:
    case MaterialType::RoughPlastic: {
      if (!(m.coat.internalReflectance >= 0.0f)) return false;
      const Vec3 o = upper(wo, flip);
      const float ps = coatProbability(m, o.z);
      if (m.type == MaterialType::Plastic && uc < ps) {
        out.wi = upper(Vec3(-o.x, -o.y, o.z), flip);
        out.pdf = ps;
        out.delta = true;
        out.weight = m.specular * (fresnelDielectric(o.z, m.ior) / ps);
        break;
      }
      Vec3 i;
      if (uc < ps) {
        i = reflect(o, microfacet::sampleVisibleNormal(m.distribution, alphaOf(m), o, u));
      } else {
        i = sampleCosineHemisphere(u);
      }
      if (!(i.z > 0.0f)) return false;
      out.pdf = coatedPdf(m, o, i);
      if (!(out.pdf > 0.0f)) return false;
      out.wi = upper(i, flip);
      out.weight = coatedEval(m, o, i) * (i.z / out.pdf);
      break;
    }
    case MaterialType::RoughDielectric: {
      // An index-matched interface refracts straight through: the transmission lobe is a delta.
      if (std::fabs(m.ior - 1.0f) < 1e-5f) {
        out.wi = -wo;
        out.pdf = 1.0f;
        out.weight = m.specular;
        out.delta = true;
        out.transmission = true;
        out.eta = 1.0f;
        break;
      }
      if (!roughDielectricSample(m, wo, uc, u, out, mode)) {
        out = BsdfSample{};
        return false;
      }
      break;
    }
  }
  if (!isFinite(out.weight) || !(out.pdf > 0.0f) || !validDir(out.wi)) {
    out = BsdfSample{};
    return false;
  }
  return true;
}

int bsdfDeltaLobes(const Material& m, const Vec3& wo, DeltaLobe out[2], TransportMode mode) {
  if (!validDir(wo) || m.blackFrom(wo.z)) return 0;
  const Vec3 wr(-wo.x, -wo.y, wo.z);
  switch (m.type) {
    case MaterialType::Mirror:
      out[0] = DeltaLobe{wr, m.specular, false};
      return 1;
    case MaterialType::Conductor:
      out[0] = DeltaLobe{wr, m.specular * fresnelConductor(wo.z, m.eta, m.k), false};
      return 1;
    case MaterialType::Plastic: {
      if (!(m.coat.internalReflectance >= 0.0f)) return 0;
      out[0] = DeltaLobe{wr, m.specular * fresnelDielectric(std::fabs(wo.z), m.ior), false};
      return 1;
    }
    case MaterialType::ThinDielectric: {
      const float r = fresnelDielectric(std::fabs(wo.z), m.ior);
      const float rt = r < 1.0f ? 2.0f * r / (1.0f + r) : 1.0f;
      out[0] = DeltaLobe{wr, m.specular * rt, false};
      if (rt >= 1.0f) return 1;
      out[1] = DeltaLobe{-wo, m.specular * (1.0f - rt), true};
      return 2;
    }
    case MaterialType::Dielectric: {
      const float fr = fresnelDielectric(wo.z, m.ior);
      out[0] = DeltaLobe{wr, m.specular * fr, false};
      float etap;
      Vec3 wt;
      if (fr >= 1.0f || !refract(wo, Vec3(0.0f, 0.0f, 1.0f), m.ior, etap, wt) || wt.z == 0.0f) return 1;
      const float t = mode == TransportMode::Radiance ? (1.0f - fr) / sqr(etap) : 1.0f - fr;
      out[1] = DeltaLobe{wt, m.specular * t, true};
      return 2;
    }
    default: return 0;
  }
}

}  // namespace voxcone

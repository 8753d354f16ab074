#pragma once
/// \file microfacet.h
/// Private to bsdf.cpp: isotropic microfacet distributions (GGX / Trowbridge-Reitz and
/// Beckmann), their Smith masking functions and visible-normal sampling.
///
/// All functions work in the local shading frame (z = macro normal). Microfacet normals `wm`
/// always lie in the upper hemisphere; directions passed to `lambda` and `g1` may be on either
/// side (only |tan theta| matters). `alpha` is the GGX alpha / Beckmann RMS slope.
///
/// References:
/// - Walter et al. 2007, "Microfacet Models for Refraction through Rough Surfaces" (EGSR), eqs.
///   25-27 (Beckmann) and 33-34 (GGX) for D and the Smith G1.
/// - Heitz 2014, "Understanding the Masking-Shadowing Function in Microfacet-Based BRDFs",
///   JCGT 3(2): Lambda (sec. 5) and the height-correlated masking-shadowing G2 (sec. 6).
/// - Heitz 2018, "Sampling the GGX Distribution of Visible Normals", JCGT 7(4), listing 1.
/// - Heitz & d'Eon 2014, "Importance Sampling Microfacet-Based BSDFs using the Distribution of
///   Visible Normals" (EGSR), sec. 4 / appendix: Beckmann visible slopes (the numerical
///   inversion of the slope CDF follows pbrt-v3's BeckmannSample11).

#include "voxcone/core/math.h"
#include "voxcone/scene/material.h"

#include <cmath>

namespace voxcone {
namespace microfacet {

constexpr double kSqrtPi = 1.77245385090551602730;

/// Normal distribution D(wm) for a unit microfacet normal; 0 below the horizon.
inline float distributionD(MicrofacetDistribution dist, float alpha, const Vec3& wm) {
  const float cos2 = wm.z * wm.z;
  if (!(wm.z > 0.0f)) return 0.0f;
  const float a2 = alpha * alpha;
  if (dist == MicrofacetDistribution::GGX) {
    // Walter 2007 eq. 33 rewritten as a^2 / (pi (cos^2 (a^2 - 1) + 1)^2): equal for unit wm and
    // free of tan/cos^4 divisions at grazing normals.
    const float t = cos2 * (a2 - 1.0f) + 1.0f;
    return a2 / (kPi * t * t);
  }
  // Beckmann, Walter 2007 eq. 25: exp(-tan^2/a^2) / (pi a^2 cos^4).
  const float sin2 = std::max(0.0f, 1.0f - cos2);
  const float e = std::exp(-sin2 / (cos2 * a2));
  const float d = e / (kPi * a2 * cos2 * cos2);
  return std::isfinite(d) ? d : 0.0f;
}

/// Smith Lambda(w) (Heitz 2014, sec. 5.1-5.2); +inf at grazing w (then G1 = 0).
inline float lambda(MicrofacetDistribution dist, float alpha, const Vec3& w) {
  const float sin2 = w.x * w.x + w.y * w.y;
  const float cos2 = w.z * w.z;
  if (sin2 == 0.0f) return 0.0f;
  if (cos2 == 0.0f) return kInf;
  if (dist == MicrofacetDistribution::GGX) {
    // Lambda = (sqrt(1 + a^2 tan^2) - 1) / 2, written without the cancellation for small t.
    const float t = alpha * alpha * sin2 / cos2;
    if (!std::isfinite(t)) return kInf;
    return t / (2.0f * (std::sqrt(1.0f + t) + 1.0f));
  }
  // Beckmann, exact: with a = 1 / (alpha tan), Lambda = (exp(-a^2) / (a sqrt(pi)) - erfc(a)) / 2.
  // Evaluated in double: the two terms nearly cancel for large a.
  const double a = std::sqrt(double(cos2) / double(sin2)) / double(alpha);
  if (a > 20.0) return 0.0f;  // exp(-400): below float resolution of 1 + Lambda
  const double l = 0.5 * (std::exp(-a * a) / (a * kSqrtPi) - std::erfc(a));
  return static_cast<float>(std::max(0.0, l));
}

/// Smith masking G1(w) = 1 / (1 + Lambda(w)).
inline float g1(MicrofacetDistribution dist, float alpha, const Vec3& w) {
  return 1.0f / (1.0f + lambda(dist, alpha, w));
}

/// log Gamma(x) for x >= 1 (Stirling series after shifting x to >= 8; abs. error < 1e-9).
inline double logGammaGe1(double x) {
  double shift = 1.0;
  while (x < 8.0) {
    shift *= x;
    x += 1.0;
  }
  const double ix = 1.0 / x, ix2 = ix * ix;
  const double series = ix * (1.0 / 12.0 - ix2 * (1.0 / 360.0 - ix2 * (1.0 / 1260.0 - ix2 / 1680.0)));
  return (x - 0.5) * std::log(x) - x + 0.91893853320467274178 + series - std::log(shift);
}

/// Height-correlated Smith masking-shadowing G2 (Heitz 2014, sec. 6). Reflection (wo, wi on
/// the same side): 1 / (1 + Lambda_o + Lambda_i). Transmission (opposite sides): a microfacet at
/// height h is seen from above with probability C1(h)^Lambda_o and from below with
/// (1 - C1(h))^Lambda_i, integrating over C1 uniform in [0,1] gives the Beta function
/// B(1 + Lambda_o, 1 + Lambda_i).
inline float g2(MicrofacetDistribution dist, float alpha, const Vec3& wo, const Vec3& wi, bool transmission) {
  const float lo = lambda(dist, alpha, wo);
  const float li = lambda(dist, alpha, wi);
  if (!std::isfinite(lo) || !std::isfinite(li)) return 0.0f;
  if (!transmission) return 1.0f / (1.0f + lo + li);
  const double a = lo, b = li;
  return static_cast<float>(std::exp(logGammaGe1(1.0 + a) + logGammaGe1(1.0 + b) - logGammaGe1(2.0 + a + b)));
}

/// Density of visible normals D_w(wm) = G1(w) max(0, w.wm) D(wm) / |w.z| (Heitz 2018, sec. 2),
/// for w flipped to the upper hemisphere. Integrates to 1 over wm.
inline float visibleNormalPdf(MicrofacetDistribution dist, float alpha, const Vec3& w, const Vec3& wm) {
  const Vec3 wUp = w.z < 0.0f ? -w : w;
  const float cosW = wUp.z;
  const float dotWm = glm::dot(wUp, wm);
  if (!(cosW > 0.0f) || !(dotWm > 0.0f)) return 0.0f;
  const float pdf = g1(dist, alpha, wUp) * dotWm * distributionD(dist, alpha, wm) / cosW;
  return std::isfinite(pdf) ? pdf : 0.0f;
}

/// Solve cdf(x) = u for x in [lo, hi] with safeguarded Newton steps (bisection fallback).
/// `residual(x, v, d)` sets v = cdf(x) - u and d = cdf'(x); the CDF must be non-decreasing on
/// [lo, hi]. Stops at |v| < 1e-11 or a bracket narrower than 1e-11 (far below float resolution).
template <typename F> inline double invertMonotone(F&& residual, double lo, double hi, double x) {
  for (int it = 0; it < 100; ++it) {
    if (!(x > lo && x < hi)) x = 0.5 * (lo + hi);
    double value, deriv;
    residual(x, value, deriv);
    if (std::fabs(value) < 1e-11) break;
    if (value > 0.0) hi = x;
    else lo = x;
    if (hi - lo < 1e-11) break;
    x -= value / deriv;
  }
  return x;
}

/// Approximate inverse error function (Giles 2010, "Approximating the erfinv function", single
/// precision, as in pbrt-v3 ErfInv): only a first guess for the Newton iterations below.
inline double erfInvApprox(double x) {
  x = std::clamp(x, -0.99999, 0.99999);
  double w = -std::log((1.0 - x) * (1.0 + x)), p;
  if (w < 5.0) {
    w -= 2.5;
    p = 2.81022636e-08;
    p = 3.43273939e-07 + p * w;
    p = -3.5233877e-06 + p * w;
    p = -4.39150654e-06 + p * w;
    p = 0.00021858087 + p * w;
    p = -0.00125372503 + p * w;
    p = -0.00417768164 + p * w;
    p = 0.246640727 + p * w;
    p = 1.50140941 + p * w;
  } else {
    w = std::sqrt(w) - 3.0;
    p = -0.000200214257;
    p = 0.000100950558 + p * w;
    p = 0.00134934322 + p * w;
    p = -0.00367342844 + p * w;
    p = 0.00573950773 + p * w;
    p = -0.0076224613 + p * w;
    p = 0.00943887047 + p * w;
    p = 1.00167406 + p * w;
    p = 2.83297682 + p * w;
  }
  return p * x;
}

/// Inverse of the CDF of a normal variable with variance 1/2: solves (1 + erf(x)) / 2 = u.
/// Uses erfc for the lower tail so that u near 0 stays accurate.
inline double inverseHalfGaussianCdf(double u) {
  if (u > 0.5) return -inverseHalfGaussianCdf(1.0 - u);
  u = std::max(u, 1e-300);
  return invertMonotone(
      [u](double x, double& v, double& d) {
        v = 0.5 * std::erfc(-x) - u;
        d = std::exp(-x * x) / kSqrtPi;
      },
      -27.0, 0.0, erfInvApprox(2.0 * u - 1.0));
}

/// Beckmann visible slopes for alpha = 1 and incidence cosThetaI (Heitz & d'Eon 2014). The x
/// slope has CDF C(x) = (1 + erf(x) + tan(theta) exp(-x^2) / sqrt(pi)) / (1 + erf(cot) +
/// tan exp(-cot^2)/sqrt(pi)) on (-inf, cot(theta)], inverted numerically in double; the y slope
/// is an independent Gaussian of variance 1/2.
inline void sampleBeckmannSlopes11(double cosThetaI, double u1, double u2, double& slopeX, double& slopeY) {
  const double sinThetaI = std::sqrt(std::max(0.0, 1.0 - cosThetaI * cosThetaI));
  const double tanThetaI = sinThetaI / cosThetaI;
  const double cotThetaI = sinThetaI > 0.0 ? cosThetaI / sinThetaI : kInf;
  // The CDF's normalization: 1 + erf(cot) + tan exp(-cot^2) / sqrt(pi) = 2 (1 + Lambda(theta)).
  const double erfCot = std::erf(cotThetaI);
  const double norm = 1.0 / (1.0 + erfCot + tanThetaI * std::exp(-cotThetaI * cotThetaI) / kSqrtPi);
  // First guess in the erf domain from pbrt-v3's fit of the inverse CDF (a polynomial in theta).
  const double theta = std::acos(std::clamp(cosThetaI, -1.0, 1.0));
  const double fit = 1.0 + theta * (-0.876 + theta * (0.4265 - 0.0594 * theta));
  const double b = erfCot - (1.0 + erfCot) * std::pow(1.0 - u1, fit);
  // Slopes below -27 carry probability < exp(-729): the bracket loses nothing.
  const double hi = std::min(cotThetaI, 27.0);
  slopeX = invertMonotone(
      [&](double x, double& v, double& d) {
        const double e = std::exp(-x * x);
        v = norm * (std::erfc(-x) + tanThetaI * e / kSqrtPi) - u1;
        d = norm * 2.0 / kSqrtPi * e * (1.0 - x * tanThetaI);
      },
      -27.0, hi, erfInvApprox(b));
  slopeY = inverseHalfGaussianCdf(u2);
}

/// Sample a visible microfacet normal for w (w.z > 0): GGX after Heitz 2018 (listing 1),
/// Beckmann after Heitz & d'Eon 2014. Density: visibleNormalPdf(w, wm).
inline Vec3 sampleVisibleNormal(MicrofacetDistribution dist, float alpha, const Vec3& w, const Vec2& u) {
  if (dist == MicrofacetDistribution::GGX) {
    // Stretch the view vector to the alpha = 1 configuration (hemisphere).
    const Vec3 vh = glm::normalize(Vec3(alpha * w.x, alpha * w.y, w.z));
    // Orthonormal basis around vh (T1 horizontal).
    const float lensq = vh.x * vh.x + vh.y * vh.y;
    const Vec3 t1 = lensq > 0.0f ? Vec3(-vh.y, vh.x, 0.0f) / std::sqrt(lensq) : Vec3(1.0f, 0.0f, 0.0f);
    const Vec3 t2 = glm::cross(vh, t1);
    // Uniform point on the projected area: a disk whose lower half is squashed by (1 + vh.z)/2.
    const float r = std::sqrt(u.x);
    const float phi = 2.0f * kPi * u.y;
    const float p1 = r * std::cos(phi);
    float p2 = r * std::sin(phi);
    const float s = 0.5f * (1.0f + vh.z);
    p2 = (1.0f - s) * safeSqrt(1.0f - p1 * p1) + s * p2;
    // Reproject onto the hemisphere and unstretch.
    const Vec3 nh = p1 * t1 + p2 * t2 + safeSqrt(1.0f - p1 * p1 - p2 * p2) * vh;
    return glm::normalize(Vec3(alpha * nh.x, alpha * nh.y, std::max(1e-6f, nh.z)));
  }
  // Beckmann: stretch, sample the alpha = 1 slopes, rotate to w's azimuth, unstretch.
  const DVec3 ws = glm::normalize(DVec3(double(alpha) * w.x, double(alpha) * w.y, double(w.z)));
  const double sinT = std::sqrt(ws.x * ws.x + ws.y * ws.y);
  const double cosPhi = sinT > 0.0 ? ws.x / sinT : 1.0;
  const double sinPhi = sinT > 0.0 ? ws.y / sinT : 0.0;
  double sx, sy;
  sampleBeckmannSlopes11(ws.z, u.x, u.y, sx, sy);
  const double rx = cosPhi * sx - sinPhi * sy;
  const double ry = sinPhi * sx + cosPhi * sy;
  const DVec3 wm = glm::normalize(DVec3(-double(alpha) * rx, -double(alpha) * ry, 1.0));
  return Vec3(wm);
}

}  // namespace microfacet
}  // namespace voxcone

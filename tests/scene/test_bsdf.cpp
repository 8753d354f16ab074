/// \file test_bsdf.cpp
/// BSDF tests: chi-square goodness of fit of bsdfSample against bsdfPdf (Nori's chi2test /
/// Mitsuba's ChiSquareTest), sample weight consistency, energy bounds, reciprocity, Fresnel
/// values and the delta lobes.

#include "voxcone/core/rng.h"
#include "voxcone/core/sampling.h"
#include "voxcone/scene/bsdf.h"

#include "../support/report.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <cmath>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

using namespace voxcone;

namespace {

constexpr double kPiD = 3.14159265358979323846;

Vec3 dirFromCosPhi(double cosTheta, double phi) {
  const double s = std::sqrt(std::max(0.0, 1.0 - cosTheta * cosTheta));
  return Vec3(float(s * std::cos(phi)), float(s * std::sin(phi)), float(cosTheta));
}

/// A direction at cos(theta) = c; the azimuth 0.3 rad keeps it off the bin edges.
Vec3 woAt(float c) { return glm::normalize(dirFromCosPhi(c, 0.3)); }

Material lambertian() {
  Material m;
  m.type = MaterialType::Lambertian;
  m.albedo = Vec3(0.8f, 0.5f, 0.2f);
  return m;
}

Material orenNayar(float sigmaDeg) {
  Material m;
  m.type = MaterialType::OrenNayar;
  m.albedo = Vec3(0.8f, 0.5f, 0.2f);
  m.sigmaRad = sigmaDeg * kPi / 180.0f;
  return m;
}

Material roughConductor(MicrofacetDistribution d, float alpha) {
  Material m;
  m.type = MaterialType::RoughConductor;
  m.distribution = d;
  m.roughness = alpha;
  m.eta = Vec3(0.143f, 0.374f, 1.442f);  // gold
  m.k = Vec3(3.983f, 2.385f, 1.603f);
  return m;
}

Material roughDielectric(MicrofacetDistribution d, float alpha, float ior = 1.5f) {
  Material m;
  m.type = MaterialType::RoughDielectric;
  m.distribution = d;
  m.roughness = alpha;
  m.ior = ior;
  return m;
}

/// A coated diffuse (Plastic, or RoughPlastic with `d`, `alpha`), prepared as Scene::finalize does.
Material plastic(MaterialType type, float alpha = 0.1f, MicrofacetDistribution d = MicrofacetDistribution::GGX,
                 Vec3 albedo = Vec3(0.8f, 0.5f, 0.2f), bool nonlinear = false) {
  Material m;
  m.type = type;
  m.albedo = albedo;
  m.distribution = d;
  m.roughness = alpha;
  m.ior = 1.5f;
  m.coatNonlinear = nonlinear;
  prepareMaterial(m);
  return m;
}

Material smoothDielectric(float ior = 1.5f) {
  Material m;
  m.type = MaterialType::Dielectric;
  m.ior = ior;
  return m;
}

bool relClose(double a, double b, double rel, double abs = 1e-6) {
  return std::fabs(a - b) <= rel * std::max(std::fabs(a), std::fabs(b)) + abs;
}

// ---------------------------------------------------------------------------------------------
// Chi-square machinery (after Nori's src/chi2test.cpp and hypothesis.cpp).

/// Adaptive Simpson quadrature (Lyness 1969 stopping rule, Richardson extrapolation).
double adaptiveSimpson(const std::function<double(double)>& f, double x0, double x1, double eps, int depth) {
  std::function<double(double, double, double, double, double, double, double, double, int)> rec =
      [&](double a, double b, double c, double fa, double fb, double fc, double whole, double e, int d) {
        const double m0 = 0.5 * (a + b), m1 = 0.5 * (b + c);
        const double fm0 = f(m0), fm1 = f(m1);
        const double h = c - a;
        const double left = h / 12.0 * (fa + 4.0 * fm0 + fb);
        const double right = h / 12.0 * (fb + 4.0 * fm1 + fc);
        const double both = left + right;
        if (d <= 0 || std::fabs(both - whole) < 15.0 * e) return both + (both - whole) / 15.0;
        return rec(a, m0, b, fa, fm0, fb, left, 0.5 * e, d - 1) + rec(b, m1, c, fb, fm1, fc, right, 0.5 * e, d - 1);
      };
  const double a = x0, b = 0.5 * (x0 + x1), c = x1;
  const double fa = f(a), fb = f(b), fc = f(c);
  return rec(a, b, c, fa, fb, fc, (c - a) / 6.0 * (fa + 4.0 * fb + fc), eps, depth);
}

/// Regularized lower incomplete gamma P(a, x) (Numerical Recipes, gser / gcf).
double gammaP(double a, double x) {
  if (x <= 0.0) return 0.0;
  const double gln = std::lgamma(a);
  if (x < a + 1.0) {
    double ap = a, sum = 1.0 / a, del = sum;
    for (int n = 0; n < 100000; ++n) {
      ap += 1.0;
      del *= x / ap;
      sum += del;
      if (std::fabs(del) < std::fabs(sum) * 1e-15) break;
    }
    return sum * std::exp(-x + a * std::log(x) - gln);
  }
  const double fpmin = 1e-300;
  double b = x + 1.0 - a, c = 1.0 / fpmin, d = 1.0 / b, h = d;
  for (int i = 1; i < 100000; ++i) {
    const double an = -i * (i - a);
    b += 2.0;
    d = an * d + b;
    if (std::fabs(d) < fpmin) d = fpmin;
    c = b + an / c;
    if (std::fabs(c) < fpmin) c = fpmin;
    d = 1.0 / d;
    const double del = d * c;
    h *= del;
    if (std::fabs(del - 1.0) < 1e-15) break;
  }
  return 1.0 - std::exp(-x + a * std::log(x) - gln) * h;
}

struct Chi2Case {
  std::string name;
  Material material;
  Vec3 wo;
};

/// gtest prints a failing parameter with this instead of its bytes.
void PrintTo(const Chi2Case& c, std::ostream* os) { *os << c.name; }

std::vector<Chi2Case> chi2Cases() {
  std::vector<Chi2Case> cases;
  auto add = [&](const std::string& name, const Material& m, float cosO) {
    std::ostringstream os;
    os << name << "_cos" << (cosO < 0 ? "m" : "") << int(std::lround(std::fabs(cosO) * 100.0f));
    cases.push_back({os.str(), m, woAt(cosO)});
  };
  // Diffuse: normal, oblique, grazing and the back side (two-sided).
  for (float c : {0.95f, 0.5f, 0.05f, -0.6f}) add("Lambertian", lambertian(), c);
  for (float c : {0.95f, 0.5f, 0.05f, -0.6f}) add("OrenNayar20", orenNayar(20.0f), c);
  const std::pair<MicrofacetDistribution, const char*> dists[] = {{MicrofacetDistribution::GGX, "GGX"},
                                                                   {MicrofacetDistribution::Beckmann, "Beckmann"}};
  for (const auto& [d, dn] : dists) {
    for (float a : {0.1f, 0.3f, 0.7f}) {
      const std::string base = std::string("RoughConductor") + dn + "_a" + std::to_string(int(std::lround(a * 10)));
      for (float c : {0.95f, 0.5f, 0.1f}) add(base, roughConductor(d, a), c);
    }
    add(std::string("RoughConductor") + dn + "_a3", roughConductor(d, 0.3f), -0.7f);
  }
  for (const auto& [d, dn] : dists)
    for (float a : {0.1f, 0.4f}) {
      const std::string base = std::string("RoughPlastic") + dn + "_a" + std::to_string(int(std::lround(a * 10)));
      for (float c : {0.9f, 0.3f, -0.6f}) add(base, plastic(MaterialType::RoughPlastic, a, d), c);
    }
  for (const auto& [d, dn] : dists) {
    for (float a : {0.2f, 0.5f}) {
      const std::string base = std::string("RoughDielectric") + dn + "_a" + std::to_string(int(std::lround(a * 10)));
      // Outside (+z) and inside (-z), the latter below and beyond the critical angle (41.8 deg).
      for (float c : {0.9f, 0.1f, -0.9f, -0.6f}) add(base, roughDielectric(d, a), c);
    }
  }
  return cases;
}

const std::vector<Chi2Case>& allChi2Cases() {
  static const std::vector<Chi2Case> cases = chi2Cases();
  return cases;
}

/// Samples per chi-square case: 250k by default, which keeps the 64 cases within a few seconds;
/// VOXCONE_BSDF_CHI2_SAMPLES raises it for a thorough run (1e6 passes as well).
int chi2SampleCount() {
  const char* env = std::getenv("VOXCONE_BSDF_CHI2_SAMPLES");
  const int n = env ? std::atoi(env) : 0;
  return n > 0 ? n : 250000;
}

class BsdfChi2Test : public ::testing::TestWithParam<Chi2Case> {};

TEST_P(BsdfChi2Test, SampleMatchesPdfAndWeights) {
  const Chi2Case& tc = GetParam();
  const Material& m = tc.material;
  const Vec3 wo = tc.wo;
  constexpr int kCos = 32, kPhi = 64;
  const int kSamples = chi2SampleCount();
  constexpr double kMinExpected = 5.0;
  // Sidak correction: family-wise significance 0.01 over every chi-square case.
  const double alpha = 1.0 - std::pow(1.0 - 0.01, 1.0 / double(allChi2Cases().size()));

  auto binOf = [&](const Vec3& w) {
    const double c = std::clamp(double(w.z), -1.0, 1.0);
    double phi = std::atan2(double(w.y), double(w.x));
    if (phi < 0.0) phi += 2.0 * kPiD;
    const int ic = std::min(kCos - 1, int((c + 1.0) * 0.5 * kCos));
    const int ip = std::min(kPhi - 1, int(phi / (2.0 * kPiD) * kPhi));
    return ic * kPhi + ip;
  };

  // Draw samples (deterministic seed per case) and check each sample against eval/pdf.
  std::vector<double> observed(kCos * kPhi, 0.0);
  Rng rng(0x5eed, std::hash<std::string>{}(tc.name));
  int weightMismatch = 0, pdfMismatch = 0, nonFinite = 0, accepted = 0;
  std::string firstMismatch;
  for (int s = 0; s < kSamples; ++s) {
    const TransportMode mode = (s & 1) ? TransportMode::Importance : TransportMode::Radiance;
    const float uc = rng.uniform();
    const Vec2 u = rng.uniform2();
    BsdfSample bs;
    if (!bsdfSample(m, wo, uc, u, bs, mode)) continue;
    ++accepted;
    if (!isFinite(bs.weight) || !isFinite(bs.wi) || !std::isfinite(bs.pdf) || bs.delta) {
      ++nonFinite;
      continue;
    }
    observed[binOf(bs.wi)] += 1.0;
    const float pdf = bsdfPdf(m, wo, bs.wi);
    const Vec3 f = bsdfEval(m, wo, bs.wi, mode);
    if (!relClose(pdf, bs.pdf, 1e-3, 0.0)) {
      if (pdfMismatch++ == 0) {
        std::ostringstream os;
        os << "pdf " << pdf << " vs sample pdf " << bs.pdf << " wi (" << bs.wi.x << "," << bs.wi.y << "," << bs.wi.z
           << ")";
        firstMismatch += os.str() + "; ";
      }
    }
    for (int ch = 0; ch < 3; ++ch) {
      const double expect = pdf > 0.0f ? double(f[ch]) * std::fabs(bs.wi.z) / pdf : 0.0;
      if (!relClose(bs.weight[ch], expect, 1e-3, 1e-7)) {
        if (weightMismatch++ == 0) {
          std::ostringstream os;
          os << "weight " << bs.weight[ch] << " vs f|cos|/pdf " << expect << " wi (" << bs.wi.x << "," << bs.wi.y
             << "," << bs.wi.z << ")";
          firstMismatch += os.str() + "; ";
        }
        break;
      }
    }
  }
  EXPECT_EQ(nonFinite, 0);
  EXPECT_EQ(pdfMismatch, 0) << firstMismatch;
  EXPECT_EQ(weightMismatch, 0) << firstMismatch;
  EXPECT_GT(accepted, kSamples / 2);

  // Expected counts: the pdf integrated over each (cos theta, phi) bin; d(omega) = dcos dphi.
  std::vector<double> expected(kCos * kPhi, 0.0);
  double total = 0.0;
  for (int ic = 0; ic < kCos; ++ic) {
    const double c0 = -1.0 + 2.0 * ic / kCos, c1 = -1.0 + 2.0 * (ic + 1) / kCos;
    for (int ip = 0; ip < kPhi; ++ip) {
      const double p0 = 2.0 * kPiD * ip / kPhi, p1 = 2.0 * kPiD * (ip + 1) / kPhi;
      // Absolute tolerance 1e-8 in probability = 0.01 expected samples per bin.
      const double eps = 1e-8;
      const double integral = adaptiveSimpson(
          [&](double c) {
            return adaptiveSimpson([&](double phi) { return double(bsdfPdf(m, wo, dirFromCosPhi(c, phi))); }, p0, p1,
                                   eps, 8);
          },
          c0, c1, eps, 8);
      expected[ic * kPhi + ip] = integral * kSamples;
      total += integral;
    }
  }
  // The pdf integrates to at most one (less where samples are rejected below the horizon), and
  // the accepted fraction must match that integral.
  EXPECT_LE(total, 1.0 + 1e-3);
  EXPECT_NEAR(double(accepted) / kSamples, total, 5e-3);

  // Pool low-expectation bins (Nori's chi2test) and form the statistic.
  std::vector<int> order(kCos * kPhi);
  for (int i = 0; i < int(order.size()); ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](int a, int b) { return expected[a] < expected[b]; });
  double chi2 = 0.0, pooledObs = 0.0, pooledExp = 0.0;
  int dof = 0;
  for (int i : order) {
    if (expected[i] <= 0.0) {
      // Samples where the pdf integrates to zero: allow only round-off strays (Nori: 1e-5 N).
      EXPECT_LE(observed[i], kSamples * 1e-5) << "samples in a bin of zero expected frequency";
    } else if (expected[i] < kMinExpected || (pooledExp > 0.0 && pooledExp < kMinExpected)) {
      pooledObs += observed[i];
      pooledExp += expected[i];
    } else {
      chi2 += sqr(observed[i] - expected[i]) / expected[i];
      ++dof;
    }
  }
  if (pooledExp > 0.0) {
    chi2 += sqr(pooledObs - pooledExp) / pooledExp;
    ++dof;
  }
  dof -= 1;
  ASSERT_GT(dof, 0);
  const double pValue = 1.0 - gammaP(0.5 * dof, 0.5 * chi2);
  EXPECT_GT(pValue, alpha) << "chi2 = " << chi2 << ", dof = " << dof << ", accepted " << accepted;
}

INSTANTIATE_TEST_SUITE_P(BsdfChi2, BsdfChi2Test, ::testing::ValuesIn(allChi2Cases()),
                         [](const ::testing::TestParamInfo<Chi2Case>& info) { return info.param.name; });

// ---------------------------------------------------------------------------------------------
// Energy

/// Mean sample weight per channel (failed samples count as zero): the directional albedo.
Vec3 meanWeight(const Material& m, const Vec3& wo, int n, TransportMode mode, uint64_t stream) {
  Rng rng(7, stream);
  DVec3 sum(0.0);
  for (int s = 0; s < n; ++s) {
    BsdfSample bs;
    const float uc = rng.uniform();
    const Vec2 u = rng.uniform2();
    if (bsdfSample(m, wo, uc, u, bs, mode)) sum += DVec3(bs.weight);
  }
  return Vec3(sum / double(n));
}

TEST(BsdfEnergy, LambertianAlbedo) {
  const Material m = lambertian();
  for (float c : {0.9f, 0.3f, -0.5f}) {
    const Vec3 a = meanWeight(m, woAt(c), 20000, TransportMode::Radiance, 1);
    for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(a[ch], m.albedo[ch], 0.01f * m.albedo[ch]);
  }
  // Independent estimate from bsdfEval with uniform sphere sampling: pi * albedo/pi = albedo.
  Rng rng(3, 3);
  DVec3 sum(0.0);
  const int n = 400000;
  for (int s = 0; s < n; ++s) {
    const Vec3 wi = sampleUniformSphere(rng.uniform2());
    sum += DVec3(bsdfEval(m, woAt(0.6f), wi)) * double(std::fabs(wi.z)) / double(kUniformSpherePdf);
  }
  for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(sum[ch] / n, m.albedo[ch], 0.01 * m.albedo[ch]);
}

TEST(BsdfEnergy, OrenNayarBelowAlbedo) {
  // The qualitative model is not energy conserving in general but stays close to the albedo
  // at moderate roughness; it must never exceed it by more than a few percent.
  const Material m = orenNayar(20.0f);
  for (float c : {0.9f, 0.5f, 0.1f}) {
    const Vec3 a = meanWeight(m, woAt(c), 40000, TransportMode::Radiance, 2);
    EXPECT_LE(a.x, 1.03f * m.albedo.x);
    EXPECT_GE(a.x, 0.85f * m.albedo.x);
  }
}

/// Cosine-weighted quadrature of int f |cos| d(omega) over the side of wo (reflection only):
/// an estimate of the albedo that does not use bsdfSample.
float reflectedEnergyByQuadrature(const Material& m, const Vec3& wo, int n) {
  Rng rng(8, 8);
  double sum = 0.0;
  for (int s = 0; s < n; ++s) {
    Vec3 wi = sampleCosineHemisphere(rng.uniform2());
    if (wo.z < 0.0f) wi.z = -wi.z;
    if (wi.z == 0.0f) continue;
    sum += double(bsdfEval(m, wo, wi).x) * kPi;  // f |cos| / (|cos| / pi)
  }
  return float(sum / n);
}

TEST(BsdfEnergy, RoughConductorWhiteFurnace) {
  // A perfect reflector: eta = 0 with a huge k gives F = 1 to within 1e-7 at any angle.
  for (auto d : {MicrofacetDistribution::GGX, MicrofacetDistribution::Beckmann}) {
    for (float a : {0.1f, 0.3f, 0.7f}) {
      Material m = roughConductor(d, a);
      m.eta = Vec3(0.0f);
      m.k = Vec3(1e4f);
      for (float c : {1.0f, 0.7f, 0.3f, 0.1f, -0.7f}) {
        const float e = meanWeight(m, woAt(c), 40000, TransportMode::Radiance, 4).x;
        EXPECT_LE(e, 1.01f) << "alpha " << a << " cos " << c;
        // Single scattering loses the light a microfacet sends below the horizon. With GGX's
        // long tails a fraction alpha^2 / (1 + alpha^2) of the normals tilts beyond 45 deg, so
        // even at normal incidence alpha = 0.7 keeps only about half; alpha = 0.1 loses ~1%.
        if (a == 0.1f && std::fabs(c) >= 0.7f) {
          EXPECT_GE(e, 0.97f) << "alpha " << a << " cos " << c;
        }
        EXPECT_GE(e, 0.45f) << "alpha " << a << " cos " << c;
        // The loss is real, not a sampling artefact: quadrature of bsdfEval agrees (the
        // alpha = 0.1 lobe is too peaked for this quadrature's variance).
        if (a >= 0.3f) {
          EXPECT_NEAR(reflectedEnergyByQuadrature(m, woAt(c), 100000), e, 0.02f) << "alpha " << a << " cos " << c;
        }
      }
    }
  }
}

TEST(BsdfEnergy, RoughDielectricWhiteFurnace) {
  // Importance transport: reflection + transmission weights carry all the energy but what single
  // scattering loses to microfacets that send light into the wrong hemisphere.
  for (auto d : {MicrofacetDistribution::GGX, MicrofacetDistribution::Beckmann}) {
    const Material m = roughDielectric(d, 0.2f);
    for (float c : {1.0f, 0.7f, 0.3f, 0.1f, -1.0f, -0.8f, -0.3f}) {
      const float e = meanWeight(m, woAt(c), 40000, TransportMode::Importance, 5).x;
      EXPECT_LE(e, 1.01f) << "cos " << c;
      if (c == 1.0f) {
        EXPECT_NEAR(e, 1.0f, 0.02f) << "cos " << c;
      }
      if (c == -1.0f) {
        // From inside, GGX's tails put ~5% of the normals beyond the critical angle, whose
        // total internal reflection partly leaves through the wrong side (measured 0.955).
        EXPECT_NEAR(e, 1.0f, 0.06f) << "cos " << c;
      }
    }
  }
}

TEST(BsdfEnergy, RoughDielectricRadianceScaling) {
  // In radiance mode only the transmitted weight is divided by eta^2.
  const Material m = roughDielectric(MicrofacetDistribution::GGX, 0.3f);
  const Vec3 wo = woAt(0.8f);
  Rng rng(11, 11);
  for (int s = 0; s < 1000; ++s) {
    const float uc = rng.uniform();
    const Vec2 u = rng.uniform2();
    BsdfSample r, i;
    const bool okR = bsdfSample(m, wo, uc, u, r, TransportMode::Radiance);
    const bool okI = bsdfSample(m, wo, uc, u, i, TransportMode::Importance);
    ASSERT_EQ(okR, okI);
    if (!okR) continue;
    EXPECT_EQ(r.transmission, i.transmission);
    const float scale = r.transmission ? 1.0f / sqr(1.5f) : 1.0f;
    EXPECT_NEAR(r.weight.x, i.weight.x * scale, 1e-5f);
    EXPECT_FLOAT_EQ(r.eta, r.transmission ? 1.5f : 1.0f);
  }
}

// ---------------------------------------------------------------------------------------------
// Reciprocity

TEST(BsdfReciprocity, ReflectiveMaterialsSymmetric) {
  std::vector<Material> ms = {lambertian(), orenNayar(20.0f), orenNayar(40.0f), plastic(MaterialType::Plastic)};
  for (auto d : {MicrofacetDistribution::GGX, MicrofacetDistribution::Beckmann})
    for (float a : {0.1f, 0.3f, 0.7f}) {
      ms.push_back(roughConductor(d, a));
      ms.push_back(plastic(MaterialType::RoughPlastic, a, d));
    }
  Rng rng(5, 5);
  int nonZero = 0;
  for (const Material& m : ms) {
    for (int s = 0; s < 2000; ++s) {
      Vec3 wo = sampleUniformSphere(rng.uniform2());
      Vec3 wi = sampleUniformSphere(rng.uniform2());
      if (s & 1) wi.z = std::copysign(wi.z, wo.z);  // half the pairs on the same side
      const Vec3 a = bsdfEval(m, wo, wi), b = bsdfEval(m, wi, wo);
      for (int ch = 0; ch < 3; ++ch) EXPECT_TRUE(relClose(a[ch], b[ch], 1e-4, 1e-7)) << a[ch] << " vs " << b[ch];
      nonZero += !isBlack(a);
    }
  }
  EXPECT_GT(nonZero, 1000);
}

TEST(BsdfReciprocity, RoughDielectricAdjoint) {
  // Walter 2007 transmission satisfies f(wo, wi) / eta_i^2 = f(wi, wo) / eta_o^2; with
  // pbrt-v4's radiance scaling that is f_radiance(wo, wi) = f_importance(wi, wo) (Veach 1997,
  // sec. 5.2). Reflection is symmetric.
  Rng rng(6, 6);
  int transmitted = 0;
  for (auto d : {MicrofacetDistribution::GGX, MicrofacetDistribution::Beckmann}) {
    const Material m = roughDielectric(d, 0.4f);
    for (int s = 0; s < 4000; ++s) {
      const Vec3 wo = sampleUniformSphere(rng.uniform2());
      const Vec3 wi = sampleUniformSphere(rng.uniform2());
      const float a = bsdfEval(m, wo, wi, TransportMode::Radiance).x;
      const float b = bsdfEval(m, wi, wo, TransportMode::Importance).x;
      EXPECT_TRUE(relClose(a, b, 1e-3, 1e-7)) << a << " vs " << b;
      transmitted += (a > 0.0f && wo.z * wi.z < 0.0f);
    }
  }
  EXPECT_GT(transmitted, 500);
}

// ---------------------------------------------------------------------------------------------
// Fresnel

TEST(BsdfFresnel, DielectricValues) {
  EXPECT_NEAR(fresnelDielectric(1.0f, 1.5f), 0.04f, 1e-6f);
  EXPECT_NEAR(fresnelDielectric(-1.0f, 1.5f), 0.04f, 1e-6f);  // same from inside at normal incidence
  EXPECT_NEAR(fresnelDielectric(0.0f, 1.5f), 1.0f, 1e-6f);    // grazing from outside
  EXPECT_NEAR(fresnelDielectric(0.5f, 1.0f), 0.0f, 1e-7f);    // index matched
  // Total internal reflection beyond the critical angle asin(1/1.5) = 41.81 deg, from inside.
  const float critCos = std::sqrt(1.0f - 1.0f / (1.5f * 1.5f));
  EXPECT_EQ(fresnelDielectric(-(critCos - 1e-3f), 1.5f), 1.0f);
  EXPECT_EQ(fresnelDielectric(-0.2f, 1.5f), 1.0f);
  EXPECT_LT(fresnelDielectric(-(critCos + 1e-2f), 1.5f), 1.0f);
  // Reflectance is the same on both sides of a refracted pair (Stokes relations).
  for (float ci : {0.95f, 0.7f, 0.4f, 0.1f}) {
    const float sinT = std::sqrt(1.0f - ci * ci) / 1.5f;
    const float ct = std::sqrt(1.0f - sinT * sinT);
    EXPECT_NEAR(fresnelDielectric(ci, 1.5f), fresnelDielectric(-ct, 1.5f), 1e-5f);
  }
  // Brewster's angle tan(theta) = 1.5: the p-polarized part vanishes, F = r_s^2 / 2.
  const float cb = 1.0f / std::sqrt(1.0f + 1.5f * 1.5f);
  const float sb = 1.5f * cb;
  const float ct = std::sqrt(1.0f - sqr(sb / 1.5f));
  const float rs = (cb - 1.5f * ct) / (cb + 1.5f * ct);
  EXPECT_NEAR(fresnelDielectric(cb, 1.5f), 0.5f * rs * rs, 1e-6f);
}

TEST(BsdfFresnel, ConductorNormalIncidence) {
  auto expectNormal = [](const Vec3& eta, const Vec3& k) {
    const Vec3 f = fresnelConductor(1.0f, eta, k);
    for (int ch = 0; ch < 3; ++ch) {
      const double e = eta[ch], kk = k[ch];
      const double ref = (sqr(e - 1.0) + kk * kk) / (sqr(e + 1.0) + kk * kk);
      EXPECT_NEAR(f[ch], ref, 1e-6) << "channel " << ch;
    }
  };
  expectNormal(Vec3(0.2f), Vec3(3.0f));
  expectNormal(Vec3(1.5f, 0.5f, 2.5f), Vec3(0.0f, 1.0f, 7.0f));
  // Gold (eta 0.143, 0.374, 1.442; k 3.983, 2.385, 1.603), values worked out by hand.
  const Vec3 gold = fresnelConductor(1.0f, Vec3(0.143f, 0.374f, 1.442f), Vec3(3.983f, 2.385f, 1.603f));
  EXPECT_NEAR(gold.x, 0.966688, 1e-5);
  EXPECT_NEAR(gold.y, 0.802537, 1e-5);
  EXPECT_NEAR(gold.z, 0.324034, 1e-5);
  expectNormal(Vec3(0.143f, 0.374f, 1.442f), Vec3(3.983f, 2.385f, 1.603f));
}

TEST(BsdfFresnel, ConductorMatchesDielectricWithoutAbsorption) {
  for (float c : {1.0f, 0.8f, 0.5f, 0.2f, 0.05f}) {
    const Vec3 f = fresnelConductor(c, Vec3(1.5f), Vec3(0.0f));
    EXPECT_NEAR(f.x, fresnelDielectric(c, 1.5f), 1e-5f) << "cos " << c;
  }
  // Grazing incidence reflects everything; results stay in [0, 1].
  const Vec3 g = fresnelConductor(0.0f, Vec3(0.2f), Vec3(3.0f));
  EXPECT_NEAR(g.x, 1.0f, 1e-5f);
  for (float c = 0.0f; c <= 1.0f; c += 0.01f) {
    const Vec3 f = fresnelConductor(c, Vec3(0.143f, 0.374f, 1.442f), Vec3(3.983f, 2.385f, 1.603f));
    EXPECT_TRUE(isFinite(f) && maxComponent(f) <= 1.0f && f.x >= 0.0f && f.y >= 0.0f && f.z >= 0.0f);
  }
}

// ---------------------------------------------------------------------------------------------
// Delta materials

TEST(BsdfDelta, DielectricLobeFrequencyMatchesFresnel) {
  const Material m = smoothDielectric();
  for (float c : {0.9f, 0.2f, 0.05f, -0.9f, -0.76f}) {
    const Vec3 wo = woAt(c);
    const double fr = fresnelDielectric(c, 1.5f);
    Rng rng(9, uint64_t(c * 1000 + 2000));
    const int n = 100000;
    int refl = 0, ok = 0;
    for (int s = 0; s < n; ++s) {
      BsdfSample bs;
      const float uc = rng.uniform();
      if (!bsdfSample(m, wo, uc, rng.uniform2(), bs)) continue;
      ++ok;
      EXPECT_TRUE(bs.delta);
      if (!bs.transmission) {
        ++refl;
        EXPECT_NEAR(bs.pdf, fr, 1e-6);
        EXPECT_EQ(bs.eta, 1.0f);
      } else {
        EXPECT_NEAR(bs.pdf, 1.0 - fr, 1e-6);
      }
    }
    EXPECT_EQ(ok, n);
    // Five binomial standard deviations.
    const double sigma = std::sqrt(n * fr * (1.0 - fr));
    EXPECT_NEAR(refl, n * fr, 5.0 * sigma + 1.0) << "cos " << c;
  }
}

TEST(BsdfDelta, DielectricSnellAndWeights) {
  const float ior = 1.5f;
  const Material m = smoothDielectric(ior);
  for (float c : {0.99f, 0.7f, 0.3f, 0.02f, -0.99f, -0.8f, -0.75f}) {
    const Vec3 wo = woAt(c);
    BsdfSample bs;
    // uc just below 1 selects refraction whenever F < 1.
    ASSERT_TRUE(bsdfSample(m, wo, kOneMinusEpsilon, Vec2(0.5f), bs, TransportMode::Radiance)) << c;
    ASSERT_TRUE(bs.transmission) << c;
    const float etaI = c > 0 ? 1.0f : ior, etaT = c > 0 ? ior : 1.0f;
    const float sinI = std::sqrt(wo.x * wo.x + wo.y * wo.y), sinT = std::sqrt(bs.wi.x * bs.wi.x + bs.wi.y * bs.wi.y);
    EXPECT_NEAR(etaI * sinI, etaT * sinT, 1e-5f);
    EXPECT_LT(bs.wi.z * wo.z, 0.0f);
    EXPECT_NEAR(glm::length(bs.wi), 1.0f, 1e-5f);
    // Opposite azimuth: wi lies in the plane of wo and the normal, on the other side.
    EXPECT_NEAR(wo.x * bs.wi.y - wo.y * bs.wi.x, 0.0f, 1e-6f);
    EXPECT_LE(wo.x * bs.wi.x + wo.y * bs.wi.y, 1e-7f);
    EXPECT_FLOAT_EQ(bs.eta, etaT / etaI);
    EXPECT_NEAR(bs.weight.x, 1.0f / sqr(etaT / etaI), 1e-6f);
    BsdfSample imp;
    ASSERT_TRUE(bsdfSample(m, wo, kOneMinusEpsilon, Vec2(0.5f), imp, TransportMode::Importance));
    EXPECT_NEAR(imp.weight.x, 1.0f, 1e-6f);
  }
  // Beyond the critical angle from inside only reflection remains.
  const Vec3 wo = woAt(-0.5f);
  BsdfSample bs;
  ASSERT_TRUE(bsdfSample(m, wo, kOneMinusEpsilon, Vec2(0.5f), bs));
  EXPECT_FALSE(bs.transmission);
  EXPECT_FLOAT_EQ(bs.pdf, 1.0f);
  EXPECT_NEAR(bs.wi.z, wo.z, 1e-7f);
}

TEST(BsdfDelta, DeltaLobesSum) {
  const float ior = 1.5f;
  Material m = smoothDielectric(ior);
  m.specular = Vec3(1.0f);
  for (float c : {0.99f, 0.6f, 0.1f, -0.99f, -0.8f}) {
    const Vec3 wo = woAt(c);
    DeltaLobe lobes[2];
    const float fr = fresnelDielectric(c, ior);
    ASSERT_EQ(bsdfDeltaLobes(m, wo, lobes, TransportMode::Importance), 2) << c;
    EXPECT_NEAR(lobes[0].weight.x + lobes[1].weight.x, 1.0f, 1e-6f);
    EXPECT_NEAR(lobes[0].weight.x, fr, 1e-6f);
    EXPECT_FALSE(lobes[0].transmission);
    EXPECT_TRUE(lobes[1].transmission);
    ASSERT_EQ(bsdfDeltaLobes(m, wo, lobes, TransportMode::Radiance), 2);
    const float etap = c > 0 ? ior : 1.0f / ior;
    EXPECT_NEAR(lobes[0].weight.x + lobes[1].weight.x, fr + (1.0f - fr) / sqr(etap), 1e-6f);
    // The lobes agree with the sampled directions.
    BsdfSample bs;
    ASSERT_TRUE(bsdfSample(m, wo, kOneMinusEpsilon, Vec2(0.5f), bs));
    EXPECT_NEAR(glm::length(bs.wi - lobes[1].wi), 0.0f, 1e-6f);
  }
  DeltaLobe lobes[2];
  ASSERT_EQ(bsdfDeltaLobes(m, woAt(-0.5f), lobes), 1);  // total internal reflection
  EXPECT_NEAR(lobes[0].weight.x, 1.0f, 1e-6f);

  Material mirror;
  mirror.type = MaterialType::Mirror;
  mirror.specular = Vec3(0.9f, 0.8f, 0.7f);
  ASSERT_EQ(bsdfDeltaLobes(mirror, woAt(0.4f), lobes), 1);
  EXPECT_EQ(lobes[0].weight, mirror.specular);
  EXPECT_NEAR(lobes[0].wi.z, 0.4f, 1e-6f);

  Material cond;
  cond.type = MaterialType::Conductor;
  cond.eta = Vec3(0.143f, 0.374f, 1.442f);
  cond.k = Vec3(3.983f, 2.385f, 1.603f);
  ASSERT_EQ(bsdfDeltaLobes(cond, woAt(-0.4f), lobes), 1);  // two-sided
  const Vec3 f = fresnelConductor(0.4f, cond.eta, cond.k);
  for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(lobes[0].weight[ch], f[ch], 1e-6f);
  EXPECT_NEAR(lobes[0].wi.z, -0.4f, 1e-6f);
  BsdfSample bs;
  ASSERT_TRUE(bsdfSample(cond, woAt(0.4f), 0.3f, Vec2(0.2f), bs));
  EXPECT_TRUE(bs.delta);
  for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(bs.weight[ch], f[ch], 1e-6f);

  EXPECT_EQ(bsdfDeltaLobes(lambertian(), woAt(0.5f), lobes), 0);
  // Delta materials have no density and no finite value.
  for (const Material& d : {m, mirror, cond}) {
    EXPECT_EQ(bsdfPdf(d, woAt(0.5f), Vec3(0, 0, 1)), 0.0f);
    EXPECT_TRUE(isBlack(bsdfEval(d, woAt(0.5f), Vec3(-woAt(0.5f).x, -woAt(0.5f).y, 0.5f))));
  }
}

// ---------------------------------------------------------------------------------------------
// Robustness: grazing and invalid directions never give NaN.

TEST(BsdfRobustness, GrazingAndInvalidDirections) {
  std::vector<Material> ms = {lambertian(), orenNayar(30.0f), smoothDielectric()};
  Material mirror;
  mirror.type = MaterialType::Mirror;
  ms.push_back(mirror);
  Material cond;
  cond.type = MaterialType::Conductor;
  ms.push_back(cond);
  for (auto d : {MicrofacetDistribution::GGX, MicrofacetDistribution::Beckmann}) {
    ms.push_back(roughConductor(d, 0.001f));
    ms.push_back(roughConductor(d, 1.0f));
    ms.push_back(roughDielectric(d, 0.001f));
    ms.push_back(roughDielectric(d, 1.0f));
    ms.push_back(roughDielectric(d, 0.3f, 1.0f));
  }
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const std::vector<Vec3> dirs = {Vec3(1, 0, 0),         Vec3(0, 0, 1),        Vec3(0, 0, -1),
                                  Vec3(0.6f, 0.8f, 0.0f), Vec3(nan, 0, 1),      glm::normalize(Vec3(1, 0, 1e-7f)),
                                  glm::normalize(Vec3(1, 1, -1e-6f)), glm::normalize(Vec3(1e-8f, 0, 1)),
                                  Vec3(0.0f)};
  Rng rng(12, 12);
  for (const Material& m : ms) {
    for (const Vec3& wo : dirs) {
      for (const Vec3& wi : dirs) {
        EXPECT_TRUE(isFinite(bsdfEval(m, wo, wi)));
        EXPECT_TRUE(std::isfinite(bsdfPdf(m, wo, wi)));
      }
      for (int s = 0; s < 200; ++s) {
        BsdfSample bs;
        const float uc = rng.uniform();
        const Vec2 u = s < 4 ? Vec2(float(s & 1) * kOneMinusEpsilon, float(s >> 1) * kOneMinusEpsilon) : rng.uniform2();
        if (bsdfSample(m, wo, uc, u, bs)) {
          EXPECT_TRUE(isFinite(bs.weight) && isFinite(bs.wi) && std::isfinite(bs.pdf) && bs.pdf > 0.0f);
          EXPECT_NE(bs.wi.z, 0.0f);
        }
      }
      DeltaLobe lobes[2];
      const int n = bsdfDeltaLobes(m, wo, lobes);
      for (int i = 0; i < n; ++i) EXPECT_TRUE(isFinite(lobes[i].weight) && isFinite(lobes[i].wi));
      if (wo.z == 0.0f || !std::isfinite(wo.x)) {
        BsdfSample bs;
        EXPECT_FALSE(bsdfSample(m, wo, 0.5f, Vec2(0.5f), bs));
      }
    }
  }
  // Tiny roughness stays finite over random directions near the specular peak.
  for (auto d : {MicrofacetDistribution::GGX, MicrofacetDistribution::Beckmann}) {
    const Material rc = roughConductor(d, 0.001f), rd = roughDielectric(d, 0.001f);
    for (int s = 0; s < 1000; ++s) {
      const Vec3 wo = sampleUniformSphere(rng.uniform2());
      for (const Material* m : {&rc, &rd}) {
        BsdfSample bs;
        if (!bsdfSample(*m, wo, rng.uniform(), rng.uniform2(), bs)) continue;
        EXPECT_TRUE(isFinite(bsdfEval(*m, wo, bs.wi)));
        EXPECT_TRUE(std::isfinite(bsdfPdf(*m, wo, bs.wi)));
      }
    }
  }
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Coated diffuse (plastic, roughplastic) and the thin dielectric

/// Mean sample weight of every lobe (delta ones included) and the share of delta samples.
Vec3 meanWeightWithDelta(const Material& m, const Vec3& wo, int n, float& deltaShare) {
  Rng rng(11, 11);
  DVec3 sum(0.0);
  int delta = 0;
  for (int s = 0; s < n; ++s) {
    BsdfSample bs;
    const float uc = rng.uniform();
    const Vec2 u = rng.uniform2();
    if (!bsdfSample(m, wo, uc, u, bs)) continue;
    sum += DVec3(bs.weight);
    delta += bs.delta;
  }
  deltaShare = float(delta) / float(n);
  return Vec3(sum / double(n));
}

TEST(BsdfCoated, DiffuseFresnelReflectancesMatchTheirIntegrals) {
  // 2 int_0^1 F(mu) mu dmu for glass (n = 1.5) seen from outside and from inside (total internal
  // reflection included), integrated in double with 200k midpoints outside the project: 0.0917780
  // and 0.5963457. They satisfy 1 - Fdr_ext = n^2 (1 - Fdr_int) (the diffuse transmittances'
  // reciprocity), which makes a white coated base conserve energy below.
  const Material m = plastic(MaterialType::Plastic);
  test::report("Fdr_ext error", std::fabs(m.coat.externalAlbedo - 0.0917780f), 2e-5);
  test::report("Fdr_int error", std::fabs(m.coat.internalReflectance - 0.5963457f), 2e-5);
  test::report("T(1) error", std::fabs(m.coat.transmittance[CoatTable::kSize - 1] - 0.96f), 1e-5);
  EXPECT_NEAR(m.coat.externalAlbedo, 0.0917780f, 2e-5f);
  EXPECT_NEAR(m.coat.internalReflectance, 0.5963457f, 2e-5f);
  EXPECT_NEAR(m.coat.transmittance[CoatTable::kSize - 1], 0.96f, 1e-5f);  // 1 - ((n-1)/(n+1))^2
  // Unprepared: black, never a division by an unset table.
  Material raw = m;
  raw.coat = CoatTable{};
  EXPECT_TRUE(isBlack(bsdfEval(raw, woAt(0.5f), woAt(0.7f))));
  BsdfSample bs;
  EXPECT_FALSE(bsdfSample(raw, woAt(0.5f), 0.9f, Vec2(0.3f), bs));
}

TEST(BsdfCoated, SmoothPlasticWhiteFurnaceAndClosedForm) {
  // A white base with Mitsuba's nonlinear sum: every bounce inside returns all the light, so the
  // coat's reflection F plus the base's (1 - F) make exactly 1 at every angle.
  const Material white = plastic(MaterialType::Plastic, 0.1f, MicrofacetDistribution::GGX, Vec3(1.0f), true);
  float furnaceOff = 0.0f;
  for (float c : {0.95f, 0.5f, 0.1f, -0.7f}) {
    float share;
    const Vec3 a = meanWeightWithDelta(white, woAt(c), 200000, share);
    for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(a[ch], 1.0f, 0.01f) << "cos " << c;
    for (int ch = 0; ch < 3; ++ch) furnaceOff = std::max(furnaceOff, std::fabs(a[ch] - 1.0f));
  }
  test::report("white furnace worst |albedo - 1|", furnaceOff, 0.01);
  // Linear (the default), albedo 0.6 grey: F(mu) + (1 - F(mu)) 0.6 (1 - Fdr_ext) / (n^2 (1 - Fdr_int))
  // = F + (1 - F) 0.6 with the reciprocity above; the delta lobe sampled with probability
  // F s / (F s + (1 - F)(1 - s)), s = 1 / (1 + 0.6).
  const Material grey = plastic(MaterialType::Plastic, 0.1f, MicrofacetDistribution::GGX, Vec3(0.6f));
  float greyOff = 0.0f, shareOff = 0.0f;
  for (float c : {0.9f, 0.3f}) {
    const float f = fresnelDielectric(c, 1.5f);
    float share;
    const Vec3 a = meanWeightWithDelta(grey, woAt(c), 200000, share);
    EXPECT_NEAR(a.x, f + (1.0f - f) * 0.6f, 0.01f) << "cos " << c;
    const float s = 1.0f / 1.6f;
    EXPECT_NEAR(share, f * s / (f * s + (1.0f - f) * (1.0f - s)), 0.005f) << "cos " << c;
    greyOff = std::max(greyOff, std::fabs(a.x - (f + (1.0f - f) * 0.6f)));
    shareOff = std::max(shareOff, std::fabs(share - f * s / (f * s + (1.0f - f) * (1.0f - s))));
  }
  test::report("grey albedo worst error", greyOff, 0.01);
  test::report("delta share worst error", shareOff, 0.005);
  // The delta lobe, as Whitted-style splitting lists it: F, in the mirror direction.
  DeltaLobe lobes[2];
  ASSERT_EQ(bsdfDeltaLobes(grey, woAt(0.5f), lobes), 1);
  EXPECT_NEAR(lobes[0].weight.x, fresnelDielectric(0.5f, 1.5f), 1e-6f);
  EXPECT_NEAR(lobes[0].wi.z, woAt(0.5f).z, 1e-6f);
  // bsdfEvalBase is the whole evaluation of a smooth coat (its coat is a delta).
  const Vec3 e = bsdfEval(grey, woAt(0.5f), woAt(0.8f)), b = bsdfEvalBase(grey, woAt(0.5f), woAt(0.8f));
  EXPECT_NEAR(e.x, b.x, 1e-7f);
  // Hand value at normal incidence both ways: 0.6 / (1 - 0.5963457) / (pi 2.25) 0.96^2.
  EXPECT_NEAR(bsdfEval(grey, Vec3(0, 0, 1), Vec3(0, 0, 1)).x, 0.6 / (1.0 - 0.5963457) / (kPiD * 2.25) * 0.9216, 1e-4);
}

TEST(BsdfCoated, RoughCoatTransmittanceMatchesItsLobe) {
  // The table's 1 - T(mu) is the coat's directional albedo: here integrated from bsdfEval of the
  // coat alone (albedo 0) by uniform hemisphere sampling, independent of the table's
  // visible-normal quadrature.
  double worst = 0.0;
  for (const auto d : {MicrofacetDistribution::GGX, MicrofacetDistribution::Beckmann}) {
    const Material m = plastic(MaterialType::RoughPlastic, 0.3f, d, Vec3(0.0f));
    for (float c : {0.9f, 0.5f, 0.2f}) {
      Rng rng(13, uint64_t(c * 100));
      double sum = 0.0;
      const int n = 800000;
      for (int s = 0; s < n; ++s) {
        const Vec3 wi = sampleUniformSphere(rng.uniform2());
        if (wi.z > 0.0f) sum += double(bsdfEval(m, woAt(c), wi).x) * wi.z / double(kUniformSpherePdf);
      }
      const float x = c * float(CoatTable::kSize - 1);
      const int i = int(x);
      const float t = (1.0f - (x - float(i))) * m.coat.transmittance[i] + (x - float(i)) * m.coat.transmittance[i + 1];
      EXPECT_NEAR(sum / n, 1.0 - t, 0.004) << "cos " << c;
      worst = std::max(worst, std::fabs(sum / n - (1.0 - t)));
    }
  }
  test::report("worst |integrated albedo - (1 - T)|", worst, 0.004);
}

TEST(BsdfCoated, RoughPlasticSumsItsBaseAsMitsubaDoes) {
  // A white nonlinear base under a rough coat. Mitsuba's roughplastic takes the coat's
  // transmittance and internal reflectance from single scattering on the microfacets, so light
  // the rough coat turns below the horizon from inside is lost, not re-reflected: the base
  // returns (1 - Fdr_ext) / (n^2 (1 - Fdr_int)) of what enters, 1 for a smooth coat, less for a
  // rough one (0.73 at alpha 0.3). The sampled albedo must equal that sum, and tend to the
  // smooth coat's 1 as alpha -> 0.
  float sumOff = 0.0f, smoothOff = 0.0f;
  for (const float alpha : {0.01f, 0.3f}) {
    const Material m = plastic(MaterialType::RoughPlastic, alpha, MicrofacetDistribution::GGX, Vec3(1.0f), true);
    const float returned =
        (1.0f - m.coat.externalAlbedo) / (2.25f * (1.0f - m.coat.internalReflectance));
    if (alpha < 0.05f) test::report("alpha 0.01 returned share - 1", std::fabs(returned - 1.0f), 0.002);
    if (alpha < 0.05f) {
      EXPECT_NEAR(returned, 1.0f, 0.002f);
    }
    for (float c : {0.9f, 0.5f, 0.2f}) {
      float share;
      const Vec3 a = meanWeightWithDelta(m, woAt(c), 200000, share);
      const float x = c * float(CoatTable::kSize - 1);
      const int i = int(x);
      const float t = (1.0f - (x - float(i))) * m.coat.transmittance[i] + (x - float(i)) * m.coat.transmittance[i + 1];
      EXPECT_EQ(share, 0.0f);
      EXPECT_NEAR(a.x, (1.0f - t) + t * returned, 0.012f) << "alpha " << alpha << " cos " << c;
      if (alpha < 0.05f) {
        EXPECT_NEAR(a.x, 1.0f, 0.015f) << "cos " << c;
      }
      sumOff = std::max(sumOff, std::fabs(a.x - ((1.0f - t) + t * returned)));
      if (alpha < 0.05f) smoothOff = std::max(smoothOff, std::fabs(a.x - 1.0f));
    }
  }
  test::report("sampled albedo worst error against the sum", sumOff, 0.012);
  test::report("alpha 0.01 sampled albedo worst |a - 1|", smoothOff, 0.015);
}

TEST(BsdfThinDielectric, InterreflectionSumAndStraightTransmission) {
  Material m;
  m.type = MaterialType::ThinDielectric;
  m.ior = 1.5f;
  float lobeOff = 0.0f, weightOff = 0.0f;
  for (float c : {1.0f, 0.6f, -0.3f}) {
    const Vec3 wo = c == 1.0f ? Vec3(0, 0, 1) : woAt(c);
    const float r = fresnelDielectric(std::fabs(wo.z), 1.5f);
    DeltaLobe lobes[2];
    ASSERT_EQ(bsdfDeltaLobes(m, wo, lobes), 2);
    EXPECT_NEAR(lobes[0].weight.x, 2.0f * r / (1.0f + r), 1e-6f);
    EXPECT_NEAR(lobes[0].weight.x + lobes[1].weight.x, 1.0f, 1e-6f);
    lobeOff = std::max({lobeOff, std::fabs(lobes[0].weight.x - 2.0f * r / (1.0f + r)),
                        std::fabs(lobes[0].weight.x + lobes[1].weight.x - 1.0f)});
    EXPECT_NEAR(glm::length(lobes[1].wi + wo), 0.0f, 1e-6f);  // straight through, no refraction
    float share;
    const Vec3 a = meanWeightWithDelta(m, wo, 100000, share);
    EXPECT_NEAR(a.x, 1.0f, 1e-5f);
    EXPECT_EQ(share, 1.0f);
    weightOff = std::max(weightOff, std::fabs(a.x - 1.0f));
  }
  test::report("worst lobe weight error", lobeOff, 1e-6);
  test::report("worst |mean sample weight - 1|", weightOff, 1e-5);
  // At normal incidence: 2 (0.04) / 1.04.
  DeltaLobe lobes[2];
  bsdfDeltaLobes(m, Vec3(0, 0, 1), lobes);
  EXPECT_NEAR(lobes[0].weight.x, 0.08f / 1.04f, 1e-6f);
  EXPECT_TRUE(isBlack(bsdfEval(m, woAt(0.5f), woAt(0.5f))));
}

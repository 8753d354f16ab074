// Photon emission guided by a pilot's useful photons, in primary sample space.

#include "voxcone/photon/emission_guide.h"

#include "voxcone/core/error.h"

#include <algorithm>
#include <cmath>

namespace voxcone {

namespace {
bool powerOfTwo(int n) { return n >= 1 && n <= 1024 && (n & (n - 1)) == 0; }

/// The cell of u in [0,1) among n equal ones (u at or past 1 by rounding: the last).
int cellOf(double u, int n) { return std::clamp(int(u * double(n)), 0, n - 1); }
}  // namespace

EmissionGuide::EmissionGuide(int slices, int dirRes) : m_slices(slices), m_dirRes(dirRes) {
  if (!powerOfTwo(slices) || !powerOfTwo(dirRes))
    throw Error("EmissionGuide: slices and dirRes must be powers of two in [1, 1024]");
}

EmissionGuide EmissionGuide::fromUseful(int slices, int dirRes, const std::vector<double>& useful, double floor) {
  EmissionGuide g(slices, dirRes);
  const int n = g.bins();
  if (useful.size() != size_t(n)) throw Error("EmissionGuide: the useful counts do not match the layout");
  if (!(floor > 0.0) || floor > 1.0) throw Error("EmissionGuide: floor must lie in (0, 1]");
  double total = 0.0;
  for (double u : useful) {
    if (!(u >= 0.0) || !std::isfinite(u)) throw Error("EmissionGuide: useful counts must be finite and >= 0");
    total += u;
  }
  if (!(total > 0.0) || floor == 1.0) return g;
  g.m_uniform = false;
  g.m_pmf.resize(size_t(n));
  g.m_cdf.resize(size_t(n));
  double c = 0.0;
  for (int b = 0; b < n; ++b) {
    g.m_pmf[size_t(b)] = (1.0 - floor) * useful[size_t(b)] / total + floor / double(n);
    c += g.m_pmf[size_t(b)];
    g.m_cdf[size_t(b)] = c;
  }
  // The sum is 1 up to rounding; normalise so that the last entry is exactly 1.
  for (int b = 0; b < n; ++b) {
    g.m_pmf[size_t(b)] /= c;
    g.m_cdf[size_t(b)] /= c;
  }
  g.m_cdf.back() = 1.0;
  return g;
}

bool EmissionGuide::coarsen(double usefulTotal, double perBin, int& slices, int& dirRes) {
  while (usefulTotal < perBin * double(slices) * double(dirRes) * double(dirRes)) {
    if (dirRes > 1) {
      dirRes /= 2;
    } else if (slices > 1) {
      slices /= 2;
    } else {
      return false;
    }
  }
  return true;
}

std::vector<double> EmissionGuide::aggregate(const std::vector<double>& fine, int slices, int dirRes,
                                             int coarseSlices, int coarseDirRes) {
  if (fine.size() != size_t(slices) * size_t(dirRes) * size_t(dirRes) || coarseSlices < 1 || coarseDirRes < 1 ||
      slices % coarseSlices != 0 || dirRes % coarseDirRes != 0)
    throw Error("EmissionGuide::aggregate: the layouts do not nest");
  std::vector<double> out(size_t(coarseSlices) * size_t(coarseDirRes) * size_t(coarseDirRes), 0.0);
  const int fs = slices / coarseSlices, fd = dirRes / coarseDirRes;
  for (int s = 0; s < slices; ++s)
    for (int j = 0; j < dirRes; ++j)
      for (int i = 0; i < dirRes; ++i)
        out[(size_t(s / fs) * coarseDirRes + size_t(j / fd)) * coarseDirRes + size_t(i / fd)] +=
            fine[(size_t(s) * dirRes + size_t(j)) * dirRes + size_t(i)];
  return out;
}

int EmissionGuide::binOf(double uLight, const Vec2& uDir) const {
  return (cellOf(uLight, m_slices) * m_dirRes + cellOf(double(uDir.y), m_dirRes)) * m_dirRes +
         cellOf(double(uDir.x), m_dirRes);
}

double EmissionGuide::remap(double& uLight, Vec2& uDir) const {
  if (m_uniform) return 1.0;
  // The bin by the guided CDF, and what is left of uLight, rescaled to [0,1), for the point of
  // the bin's slice.
  const int n = bins();
  const int b = std::min(int(std::upper_bound(m_cdf.begin(), m_cdf.end(), uLight) - m_cdf.begin()), n - 1);
  const double lo = b > 0 ? m_cdf[size_t(b) - 1] : 0.0;
  const double r = std::clamp((uLight - lo) / m_pmf[size_t(b)], 0.0, std::nextafter(1.0, 0.0));
  const int s = b / (m_dirRes * m_dirRes);
  const int j = (b / m_dirRes) % m_dirRes;
  const int i = b % m_dirRes;
  uLight = std::min((double(s) + r) / double(m_slices), std::nextafter(1.0, 0.0));
  const float below1 = std::nextafter(1.0f, 0.0f);
  uDir = Vec2(std::min((float(i) + uDir.x) / float(m_dirRes), below1),
              std::min((float(j) + uDir.y) / float(m_dirRes), below1));
  return 1.0 / (double(n) * m_pmf[size_t(b)]);
}

void EmissionGuide::expectedYield(const std::vector<double>& useful, double emitted, double& usefulPerPhoton,
                                  double& effectivePerPhoton) const {
  usefulPerPhoton = effectivePerPhoton = 0.0;
  if (useful.size() != size_t(bins()) || !(emitted > 0.0)) return;
  // Bin b's rate (useful per photon emitted in it) is r_b = useful_b bins / emitted. Per guided
  // photon: useful sum_b p_b r_b; weights w_b = 1 / (bins p_b), sum w = sum_b r_b / bins
  // = U / emitted as unguided, sum w^2 = sum_b r_b / (bins^2 p_b).
  const double n = double(bins());
  double total = 0.0, sumW2 = 0.0;
  for (int b = 0; b < bins(); ++b) {
    const double u = useful[size_t(b)];
    if (!(u > 0.0)) continue;
    const double r = u * n / emitted;
    const double p = pmf(b);
    total += u;
    usefulPerPhoton += p * r;
    sumW2 += r / (n * n * p);
  }
  const double sumW = total / emitted;
  effectivePerPhoton = sumW2 > 0.0 ? sumW * sumW / sumW2 : 0.0;
}

}  // namespace voxcone

#pragma once
/// \file emission_guide.h
/// Photons guided to what the camera sees (importance-driven emission: Peter and Pietrek 1998
/// guide emission by visual importance; here the importance is measured, not traced). A photon's
/// emission is a point of primary sample space: uLight chooses the light by power, uDir the
/// direction (LightEmission::sample). The guide splits that space into bins (`slices` equal
/// intervals of uLight times a `dirRes` x `dirRes` grid of uDir; uPos and uSide are not split),
/// and a pilot pass, emitted uniformly, counts for each bin the photons it stored where the
/// camera's gathers read (SeenRegion). Guided emission draws a bin by
///   p_b = (1 - floor) useful_b / sum(useful) + floor / bins,
/// then a uniform point inside it, and weights the photon by its uniform density over the
/// guided one, 1 / (bins p_b): unbiased wherever the lights shine, as every bin keeps at least
/// floor / bins of the photons (a photon weighs at most 1 / floor of an unguided one).
///
/// The mapping from primary samples to photons is that of unguided emission, so the guide
/// works for every kind of light LightEmission emits from, without knowing its geometry.

#include "voxcone/core/math.h"

#include <cstdint>
#include <vector>

namespace voxcone {

class EmissionGuide {
public:
  /// The uniform guide of a layout: no remapping, weight 1; it only names each photon's bin.
  /// `slices` and `dirRes` are powers of two (>= 1, <= 1024).
  EmissionGuide(int slices, int dirRes);

  /// The guide from a pilot: `useful[b]` (the layout's bins) is what the pilot's photons
  /// emitted in bin b stored where they are of use (any non-negative measure), `floor` in
  /// (0, 1] the share every bin keeps in proportion to its size. With nothing useful at all,
  /// the uniform guide.
  static EmissionGuide fromUseful(int slices, int dirRes, const std::vector<double>& useful, double floor);

  /// The layout a pilot's counts can support: from the finest (`slices` x `dirRes`^2 bins),
  /// halving the direction grid and then the slices until the pilot's `usefulTotal` photons
  /// come to at least `perBin` per bin. Writes the layout; false when even one bin would have
  /// fewer than `perBin` (no guide is worth building).
  static bool coarsen(double usefulTotal, double perBin, int& slices, int& dirRes);

  /// Counts recorded in the bins of layout (slices, dirRes) summed into the coarser layout
  /// (coarseSlices, coarseDirRes) (each a power-of-two divisor of the fine one).
  static std::vector<double> aggregate(const std::vector<double>& fine, int slices, int dirRes, int coarseSlices,
                                       int coarseDirRes);

  int slices() const { return m_slices; }
  int dirRes() const { return m_dirRes; }
  int bins() const { return m_slices * m_dirRes * m_dirRes; }
  bool uniform() const { return m_uniform; }
  double pmf(int bin) const { return m_uniform ? 1.0 / bins() : m_pmf[size_t(bin)]; }

  /// The bin a (uLight, uDir) in [0,1) x [0,1)^2 falls in.
  int binOf(double uLight, const Vec2& uDir) const;
  /// Turns uniform (uLight, uDir) into a guided sample (in place) and returns its weight,
  /// 1 / (bins p_b) for the bin b drawn; uLight chooses the bin and, rescaled, the point of
  /// its slice. The uniform guide leaves them unchanged and returns 1.
  double remap(double& uLight, Vec2& uDir) const;

  /// With the pilot's `useful` counts over `emitted` uniform photons: the useful photons one
  /// guided photon is expected to store, and their effective number ((sum w)^2 / sum w^2 of the
  /// weights, per guided photon emitted): what guided photons are worth against unguided ones.
  void expectedYield(const std::vector<double>& useful, double emitted, double& usefulPerPhoton,
                     double& effectivePerPhoton) const;

private:
  int m_slices = 1;
  int m_dirRes = 1;
  bool m_uniform = true;
  std::vector<double> m_pmf;  ///< per bin (empty when uniform)
  std::vector<double> m_cdf;  ///< cumulative, the last entry exactly 1
};

}  // namespace voxcone

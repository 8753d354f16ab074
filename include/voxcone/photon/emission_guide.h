#pragma once
/// \file emission_guide.h
/// Photons guided to what the camera sees (importance-driven emission: Peter and Pietrek 1998
/// guide emission by visual importance; here the importance is measured, not traced). A photon's
/// emission is a point of a six-dimensional primary sample space (EmissionSample): uLight
/// chooses the light by power, uSide a side (or a sky's and a sun's part of its disc), uPos and
/// uDir the point and the direction (LightEmission::sample; a sky draws its direction from uDir
/// and its point on the disc from uPos, a sun the reverse). A pilot pass, emitted uniformly,
/// records the samples of the photons it stored where the camera's gathers read (SeenRegion),
/// and the guide is a kd-tree over that space built on them (as Mueller et al. 2017's SD-tree
/// refines where the samples are): a box holding at least `splitCount` useful samples is cut in
/// two along the dimension whose cut most raises their likelihood under a piecewise-constant
/// density (at the middle, or for uLight at the edge between two lights nearest the middle), so
/// the boxes are small where useful photons crowd (the directions and the points of a sky's
/// disc that pass a window) and large where there are none. Guided emission draws leaf b with
/// probability p_b = vol_b rho_b / sum_c vol_c rho_c, where its density
///   rho_b = max(d_b, d_typical / maxRatio),  d_b = (1 - floor) useful_b / (sum(useful) vol_b) + floor,
/// d_typical the mean of d over the useful stores (the density a typical useful photon is drawn with),
/// then a uniform point inside it, and weights the photon by its uniform density over the
/// guided one, vol_b / p_b: unbiased wherever the lights shine, as every leaf keeps at least
/// floor of its volume's photons (a photon weighs at most 1 / floor of an unguided one), and no
/// photon weighs more than maxRatio times a typical useful one. That bound is what keeps the
/// estimates smooth: unbounded, the pilot's favoured leaves came out 128 times denser than the
/// rest on tools/make_gltf_room.py --held-out-2, and the few photons from the rest (light
/// through the window from the leaves' edges) each carried 500 times their neighbours' power,
/// blotches of up to 1.4 times Cycles over a 32x32 block.
///
/// The mapping from primary samples to photons is that of unguided emission, so the guide
/// works for every kind of light LightEmission emits from, without knowing its geometry.

#include "voxcone/core/math.h"

#include <array>
#include <cstdint>
#include <vector>

namespace voxcone {

/// A point of a photon's primary sample space, each coordinate in [0, 1).
struct EmissionSample {
  double uLight = 0.0;
  float uSide = 0.0f;
  Vec2 uPos{0.0f};
  Vec2 uDir{0.0f};

  static constexpr int kDims = 6;
  /// Coordinate d: uLight, uSide, uPos.x, uPos.y, uDir.x, uDir.y.
  double get(int d) const;
  void set(int d, double v);
};

class EmissionGuide {
public:
  /// The uniform guide: no remapping, weight 1, one leaf.
  EmissionGuide();

  /// One pilot photon of use: where it was emitted from, and how many of its stores were of use.
  struct Useful {
    EmissionSample sample;
    double stores = 1.0;
  };

  /// The guide from a pilot's `useful` photons (each emitted once: a photon stored five times
  /// where it is of use is one sample of stores 5, not five samples at one point); `lightEdges` the values of uLight where one light's choice ends and the next
  /// one's begins (increasing, inside (0, 1)); `floor` in (0, 1] the share every leaf keeps in
  /// proportion to its volume; a box is cut while it holds at least `splitCount` (>= 2) useful
  /// photons; its density follows their stores, and is at least the typical useful photon's
  /// over `maxRatio` (>= 1). With no useful sample, or floor 1, the uniform guide.
  static EmissionGuide fromUseful(std::vector<Useful> useful, const std::vector<double>& lightEdges,
                                  double floor, double splitCount, double maxRatio);

  bool uniform() const { return m_uniform; }
  size_t leaves() const { return m_leaves.size(); }
  double pmf(size_t leaf) const { return m_leaves[leaf].pmf; }
  double volume(size_t leaf) const { return m_leaves[leaf].volume; }
  /// The useful stores of the photons the leaf was built on.
  double useful(size_t leaf) const { return m_leaves[leaf].useful; }
  /// The leaf's box, per dimension [lo, hi).
  const std::array<double, 12>& box(size_t leaf) const { return m_leaves[leaf].box; }

  /// The leaf a sample falls in.
  size_t leafOf(const EmissionSample& u) const;
  /// Turns a uniform sample into a guided one (in place) and returns its weight, vol_b / p_b for
  /// the leaf b drawn: uLight chooses the leaf and, rescaled, its coordinate inside it; the
  /// others are placed inside the leaf's box. The uniform guide leaves it unchanged and returns 1.
  double remap(EmissionSample& u) const;

  /// With the pilot's `useful` samples per leaf over `emitted` uniform photons: the useful
  /// photons one guided photon is expected to store, and their effective number ((sum w)^2 /
  /// sum w^2 of the weights, per guided photon emitted): what guided photons are worth against
  /// unguided ones. The counts the guide was built on when `useful` is empty.
  void expectedYield(double emitted, double& usefulPerPhoton, double& effectivePerPhoton,
                     const std::vector<double>& useful = {}) const;

  /// expectedYield judged on photons the guide was not built on (two-fold cross-validation): the
  /// guide of each half of `useful` (alternate photons, of `emitted` in all) with the other half's
  /// stores in its leaves, the two averaged. The yield of the guide built on all of them judged on
  /// them is optimistic, as its cuts follow those very photons: the sunlit hall's pass stored 16%
  /// fewer useful photons than that promised.
  static void heldOutYield(const std::vector<Useful>& useful, const std::vector<double>& lightEdges, double floor,
                           double splitCount, double maxRatio, double emitted, double& usefulPerPhoton,
                           double& effectivePerPhoton);

private:
  /// [0, 1) in every dimension.
  static std::array<double, 12> unitBox();
  struct Leaf {
    std::array<double, 12> box{};  ///< lo, hi per dimension
    double volume = 1.0;
    double useful = 0.0;
    double pmf = 1.0;
  };
  /// An inner node cuts dimension `dim` at `cut`: below goes to node `child`, the rest to
  /// child + 1; a leaf (dim < 0) names its leaf in `child`.
  struct Node {
    int dim = -1;
    double cut = 0.0;
    uint32_t child = 0;
  };
  bool m_uniform = true;
  std::vector<Node> m_nodes;
  std::vector<Leaf> m_leaves;
  std::vector<double> m_cdf;  ///< over the leaves, the last entry exactly 1
};

}  // namespace voxcone

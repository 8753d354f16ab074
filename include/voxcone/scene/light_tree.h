#pragma once
/// \file light_tree.h
/// A light tree: a binary tree over the scene's bounded lights (emissive triangles and point
/// lights) whose nodes bound their lights' positions, emission directions and power, so that a
/// shading point chooses a light by its estimated contribution there (power over squared
/// distance, times bounds on the emitter's and the receiver's cosines) in O(log N) importance
/// evaluations. Conty Estevez and Kulla, "Importance Sampling of Many Lights with Adaptive Tree
/// Splitting" (2018), as pbrt-v4's BVHLightSampler states it: one light per leaf, the tree
/// built by the surface-area-orientation heuristic over 12 bins per axis, the choice walking
/// down from the root with one uniform number rescaled at each node (so a stratified set of
/// numbers stays stratified over the lights), and the probability of any light recomputed from
/// its leaf up (for multiple importance sampling).

#include "voxcone/core/bounds.h"
#include "voxcone/core/math.h"

#include <cstdint>
#include <vector>

namespace voxcone {

/// What a light, or a node's lights together, can emit and where: the bounds of its positions,
/// a cone of emission normals (axis w, half-angle acos(cosTheta_o)), how far beyond a normal
/// the emission reaches (acos(cosTheta_e): pi/2 for a Lambertian emitter), its power.
struct LightBounds {
  Bounds3 bounds;
  Vec3 w{0.0f, 0.0f, 1.0f};
  float phi = 0.0f;           ///< power (luminance of the flux, W)
  float cosTheta_o = 1.0f;    ///< the normals' cone; -1: every direction (a point light)
  float cosTheta_e = 0.0f;    ///< cos(pi/2) for Lambertian emitters and point lights
  bool twoSided = false;      ///< emits on both sides of its normals

  /// An upper-bound estimate of the light's contribution at point p: phi / d^2 times the bound
  /// on the emitter's cosine towards p and, with a normal n (unit; the receiver's, either side
  /// of it), the bound on the receiver's |cos|. Zero only where no point of the bounds can
  /// emit towards p (behind a one-sided emitter) or reach p's tangent plane from above or below.
  float importance(const Vec3& p, const Vec3* n) const;
};

/// The bounds of two lights' bounds together.
LightBounds unite(const LightBounds& a, const LightBounds& b);

/// LightBounds as importance() reads them, with what it would otherwise recompute at every call
/// (the box's bounding sphere, the cone's sine): the tree's nodes keep these.
struct ImportanceBounds {
  Vec3 centre{0.0f};
  float r2 = 0.0f, r = 0.0f;  ///< the box's bounding sphere: radius squared, radius
  Vec3 w{0.0f, 0.0f, 1.0f};
  float phi = 0.0f;
  float cosTheta_o = 1.0f, sinTheta_o = 0.0f, cosTheta_e = 0.0f;
  bool twoSided = false;

  static ImportanceBounds of(const LightBounds& b);
  /// LightBounds::importance.
  float importance(const Vec3& p, const Vec3* n) const;
};

class LightTree {
public:
  LightTree() = default;
  /// Builds over `lights`; light i keeps its index i. Lights with phi <= 0 are never chosen.
  explicit LightTree(const std::vector<LightBounds>& lights);

  bool empty() const { return m_nodes.empty(); }
  size_t nodeCount() const { return m_nodes.size(); }

  /// Chooses a light for point p (normal n, or null) with u in [0, 1): its index and the
  /// probability of choosing it; u is rescaled in place to [0, 1) within the chosen light's
  /// share (for the point on the light). False when no light can reach p.
  bool sample(const Vec3& p, const Vec3* n, float& u, uint32_t& light, float& pmf) const;
  /// The probability that sample() at (p, n) chooses `light`.
  float pmf(const Vec3& p, const Vec3* n, uint32_t light) const;

  /// One chosen light of sampleSplit: the light, the probability of choosing it within its
  /// group, and u rescaled within its share (for the point on the light).
  struct Choice {
    uint32_t light = 0;
    float pmf = 0.0f;
    float u = 0.0f;
  };
  /// Most choices sampleSplit makes: it splits nodes down to depth kSplitDepth only.
  static constexpr int kSplitDepth = 4;
  static constexpr int kMaxChoices = 1 << kSplitDepth;
  /// Adaptive splitting (Conty Estevez and Kulla 2018, sec. 5): the walk down sample() takes,
  /// but at a node (of depth below kSplitDepth) that p sees too wide to trust one estimate of
  /// (p inside its bounding sphere, or the sphere's angular radius above `splitAngle`,
  /// radians) both children are walked, each a group of its own: the lights' estimates add up.
  /// Writes up to kMaxChoices choices to `out`; returns how many. splitAngle >= pi/2: sample()'s
  /// single choice (except from inside a node's sphere).
  int sampleSplit(const Vec3& p, const Vec3* n, float u, float splitAngle, Choice* out) const;
  /// The probability that sampleSplit at (p, n) chooses `light` within its group.
  float pmfSplit(const Vec3& p, const Vec3* n, uint32_t light, float splitAngle) const;

private:
  struct Node {
    ImportanceBounds ib;      ///< what sample() and pmf() read
    LightBounds lb;
    uint32_t parent = UINT32_MAX;
    uint32_t second = 0;      ///< internal: the second child (the first is the next node)
    uint32_t light = 0;       ///< leaf: the light
    uint8_t depth = 0;        ///< the root's is 0
    bool leaf = false;
  };
  /// Does sampleSplit walk both children of `node` at p?
  bool splits(const Node& node, const Vec3& p, float sinSplit2) const;
  /// The probability that the walk at internal node i takes its first child (the children's
  /// importances normalized); negative where neither child can reach p.
  float firstChildProbability(uint32_t i, const Vec3& p, const Vec3* n) const;
  /// One step of the walk down from internal node i: the child u chooses by
  /// firstChildProbability, u rescaled within its share and pmf multiplied by it; UINT32_MAX
  /// where neither child can reach p.
  uint32_t descend(uint32_t i, const Vec3& p, const Vec3* n, float& u, float& pmf) const;
  /// The probability of choosing `light`, from its leaf up; with `split`, nodes that split
  /// (at sinSplit2, the split angle's sine squared) count as certain.
  float pmfUp(const Vec3& p, const Vec3* n, uint32_t light, bool split, float sinSplit2) const;
  uint32_t build(std::vector<uint32_t>& idx, size_t begin, size_t end, const std::vector<LightBounds>& lights,
                 uint32_t parent);

  std::vector<Node> m_nodes;
  std::vector<uint32_t> m_leafOf;  ///< per light: its leaf node, or UINT32_MAX
};

}  // namespace voxcone

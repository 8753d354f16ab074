#pragma once
/// \file kdtree.h
/// An SAH kd-tree over triangles, for the structures study against the HBVH (hbvh.h). Built
/// top down with binned min/max SAH (Shevtsov, Soupikov & Kapustin 2007, "Highly Parallel Fast
/// KD-tree Construction for Interactive Ray Tracing of Dynamic Scenes"): per axis, the planes
/// between bins are costed from histograms of where primitives start and end; primitives that
/// straddle the plane go to both sides with their boxes clipped to each. The empty-space bonus,
/// depth limit and bad-refine allowance follow pbrt's kd-tree (Pharr, Jakob & Humphreys,
/// sec. 4.4). Nodes are 8 bytes, the below child follows its parent; leaves hold their
/// triangles in the same 4-wide packets as the HBVH, so the comparison is of structures, not
/// of triangle tests.

#include "voxcone/accel/accel.h"
#include "voxcone/accel/triangle.h"

namespace voxcone {

struct KdTreeBuildSettings {
  int binCount = 32;             ///< candidate planes per axis and node: binCount - 1, [2, 256]
  int maxLeafSize = 8;           ///< larger leaves are split even at a cost (up to 3 times in a row)
  float traversalCost = 1.0f;    ///< SAH cost of one inner-node step
  float intersectionCost = 1.0f; ///< SAH cost of one 4-triangle packet test
  float emptyBonus = 0.5f;       ///< cost reduction for a split with an empty side
  int maxDepth = 0;              ///< 0: 8 + 1.3 log2(triangles) (pbrt), at most 60
  int parallelThreshold = 4096;  ///< subtrees with fewer references are built by one task
};

struct KdTreeStats {
  uint64_t triangles = 0;
  uint64_t nodes = 0;       ///< inner nodes and leaves
  uint64_t leaves = 0;
  uint64_t emptyLeaves = 0;
  uint64_t references = 0;  ///< triangle references in leaves (a straddling triangle counts per leaf)
  int maxDepth = 0;
  double sahCost = 0.0;     ///< SAH cost of the tree, relative to the root's area
  uint64_t bytes = 0;       ///< nodes and leaf packets
  double buildSeconds = 0.0;
};

class KdTree final : public Accel {
public:
  /// 8-byte node. Inner: split position, axis in the low 2 bits, the above child's index in the
  /// rest (the below child is the next node). Leaf: first packet, low bits 3, packet count above.
  struct Node {
    union {
      float split;
      uint32_t firstPacket;
    };
    uint32_t bits;
    bool leaf() const { return (bits & 3u) == 3u; }
    int axis() const { return static_cast<int>(bits & 3u); }
    uint32_t aboveChild() const { return bits >> 2; }
    uint32_t packetCount() const { return bits >> 2; }
  };

  KdTree() = default;
  KdTree(const std::vector<Vec3>& positions, const std::vector<UVec3>& triangles,
         const KdTreeBuildSettings& settings = {}, Progress* progress = nullptr);

  std::optional<Hit> intersect(const Ray& ray) const override;
  bool occluded(const Ray& ray, float tMax) const override;
  using Accel::occluded;
  Bounds3 bounds() const override { return m_bounds; }
  std::string kind() const override { return "kdtree"; }
  uint64_t bytes() const override { return m_stats.bytes; }
  double buildSeconds() const override { return m_stats.buildSeconds; }
  nlohmann::json statsJson() const override;
  const KdTreeStats& stats() const { return m_stats; }

private:
  struct Builder;
  /// The ray's parametric range [t0, t1] inside the root box and (tMin, tMax), or false when
  /// it misses.
  bool clipToBounds(const Ray& ray, const float invDir[3], float tMax, float& t0, float& t1) const;
  /// Front-to-back traversal: the closest hit below tMax into `hit`, or (kAnyHit) any hit.
  template <bool kAnyHit>
  bool traverse(const Ray& ray, float tMax, Hit& hit) const;

  KdTreeBuildSettings m_settings;
  KdTreeStats m_stats;
  Bounds3 m_bounds;
  std::vector<Node> m_nodes;
  std::vector<Triangle4> m_tris;
};

}  // namespace voxcone

#pragma once
/// \file photon_kdtree.h
/// A balanced 3-d tree over photon positions (Jensen 2001, "Realistic Image Synthesis Using
/// Photon Mapping", sec. 6.3-6.4): built by median splits along the axis of largest extent,
/// stored implicitly (the node of index range [lo, hi) is element (lo + hi) / 2), queried for
/// the k nearest points within a maximum radius with a bounded max-heap (Jensen's
/// locate_photons).

#include "voxcone/core/math.h"

#include <cstdint>
#include <vector>

namespace voxcone {

/// One result of a nearest-neighbour query.
struct KdNeighbor {
  uint32_t index = 0;  ///< index into the positions the tree was built from
  float dist2 = 0.0f;  ///< squared distance to the query point, world units^2
};

/// Balanced kd-tree over points. Immutable after construction; queries are thread-safe.
class PhotonKdTree {
public:
  PhotonKdTree() = default;
  /// Build over `positions` (world space). Deterministic: the same input gives the same tree
  /// (std::nth_element on a fixed order, ties broken by index). At most 2^32 - 1 points.
  explicit PhotonKdTree(const std::vector<Vec3>& positions);

  /// Number of points in the tree.
  size_t size() const { return m_pos.size(); }
  bool empty() const { return m_pos.empty(); }

  /// The at most `k` (>= 1) nearest points with squared distance <= `maxDist2` (world
  /// units^2; pass infinity for no limit) to `query`, written to `out` (cleared first) in
  /// order of increasing distance (ties by increasing index). Returns out.size().
  size_t knn(const Vec3& query, int k, float maxDist2, std::vector<KdNeighbor>& out) const;

private:
  void build(uint32_t lo, uint32_t hi, std::vector<uint32_t>& order, const std::vector<Vec3>& positions);
  void search(uint32_t lo, uint32_t hi, const Vec3& q, size_t k, float maxDist2, std::vector<KdNeighbor>& heap) const;

  std::vector<Vec3> m_pos;        ///< positions in tree order
  std::vector<uint32_t> m_index;  ///< original index of each tree-order element
  std::vector<uint8_t> m_axis;    ///< split axis of the node at each element (0, 1, 2)
};

}  // namespace voxcone

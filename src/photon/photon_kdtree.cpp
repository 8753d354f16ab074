// Balanced kd-tree over photon positions (Jensen 2001, sec. 6.3-6.4), implicit layout.

#include "voxcone/photon/photon_kdtree.h"

#include "voxcone/core/error.h"

#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <limits>

namespace voxcone {

namespace {
/// Max-heap order on distance (ties: larger index on top), so the heap top is the worst kept.
/// A function object, so the heap algorithms inline it (as a function pointer it was 5% of a
/// render's profile on small-objects, called through the pointer).
struct HeapLess {
  bool operator()(const KdNeighbor& a, const KdNeighbor& b) const {
    return a.dist2 < b.dist2 || (a.dist2 == b.dist2 && a.index < b.index);
  }
};
constexpr HeapLess heapLess{};
/// Ranges at least this large build their two halves in parallel (the same tree: the halves
/// are disjoint).
constexpr uint32_t kParallelBuild = 1u << 14;
/// Ranges of at most this many points are leaves, searched point by point (the result is the
/// same: the k nearest by (distance, index) are one set however they are visited).
constexpr uint32_t kLeaf = 8;
}  // namespace

PhotonKdTree::PhotonKdTree(const std::vector<Vec3>& positions) {
  if (positions.size() >= std::numeric_limits<uint32_t>::max())
    throw SettingsError("photon kd-tree: too many points (" + std::to_string(positions.size()) + ")");
  const uint32_t n = static_cast<uint32_t>(positions.size());
  std::vector<uint32_t> order(n);
  for (uint32_t i = 0; i < n; ++i) order[i] = i;
  m_axis.assign(n, 0);
  build(0, n, order, positions);
  m_pos.resize(n);
  m_index = std::move(order);
  for (uint32_t i = 0; i < n; ++i) m_pos[i] = positions[m_index[i]];
}

void PhotonKdTree::build(uint32_t lo, uint32_t hi, std::vector<uint32_t>& order, const std::vector<Vec3>& positions) {
  if (hi - lo <= kLeaf) return;
  // Split along the axis of largest extent of this range's bounds (Jensen's balance()).
  Vec3 bmin(std::numeric_limits<float>::infinity()), bmax(-std::numeric_limits<float>::infinity());
  for (uint32_t i = lo; i < hi; ++i) {
    bmin = glm::min(bmin, positions[order[i]]);
    bmax = glm::max(bmax, positions[order[i]]);
  }
  const Vec3 ext = bmax - bmin;
  const int axis = ext.x >= ext.y && ext.x >= ext.z ? 0 : (ext.y >= ext.z ? 1 : 2);
  const uint32_t mid = lo + (hi - lo) / 2;
  // Median by (coordinate, index): a strict total order, so the result does not depend on
  // the nth_element implementation's handling of equal keys.
  std::nth_element(order.begin() + lo, order.begin() + mid, order.begin() + hi, [&](uint32_t a, uint32_t b) {
    const float ca = positions[a][axis], cb = positions[b][axis];
    return ca < cb || (ca == cb && a < b);
  });
  m_axis[mid] = static_cast<uint8_t>(axis);
  if (hi - lo >= kParallelBuild) {
    tbb::parallel_invoke([&] { build(lo, mid, order, positions); }, [&] { build(mid + 1, hi, order, positions); });
  } else {
    build(lo, mid, order, positions);
    build(mid + 1, hi, order, positions);
  }
}

size_t PhotonKdTree::knn(const Vec3& query, int k, float maxDist2, std::vector<KdNeighbor>& out) const {
  out.clear();
  if (k <= 0 || m_pos.empty()) return 0;
  search(0, static_cast<uint32_t>(m_pos.size()), query, static_cast<size_t>(k), maxDist2, out);
  std::sort_heap(out.begin(), out.end(), heapLess);
  return out.size();
}

void PhotonKdTree::search(uint32_t lo, uint32_t hi, const Vec3& q, size_t k, float maxDist2,
                          std::vector<KdNeighbor>& heap) const {
  // Candidate test: inside the radius, and better than the worst kept once k are kept.
  const auto consider = [&](uint32_t i) {
    const Vec3 d = q - m_pos[i];
    const float d2 = glm::dot(d, d);
    if (!(d2 <= maxDist2)) return;
    const KdNeighbor cand{m_index[i], d2};
    if (heap.size() < k) {
      heap.push_back(cand);
      std::push_heap(heap.begin(), heap.end(), heapLess);
    } else if (heapLess(cand, heap.front())) {
      std::pop_heap(heap.begin(), heap.end(), heapLess);
      heap.back() = cand;
      std::push_heap(heap.begin(), heap.end(), heapLess);
    }
  };
  while (lo < hi) {
    if (hi - lo <= kLeaf) {
      for (uint32_t i = lo; i < hi; ++i) consider(i);
      return;
    }
    const uint32_t mid = lo + (hi - lo) / 2;
    consider(mid);
    // Near side first; the far side only while the splitting plane is within the bound.
    const float delta = q[m_axis[mid]] - m_pos[mid][m_axis[mid]];
    uint32_t nearLo = lo, nearHi = mid, farLo = mid + 1, farHi = hi;
    if (delta >= 0.0f) std::swap(nearLo, farLo), std::swap(nearHi, farHi);
    search(nearLo, nearHi, q, k, maxDist2, heap);
    const float bound = heap.size() < k ? maxDist2 : heap.front().dist2;
    if (delta * delta > bound) return;
    lo = farLo;
    hi = farHi;
  }
}

}  // namespace voxcone

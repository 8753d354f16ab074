// SAH kd-tree: binned min/max build (kdtree.h) and front-to-back traversal with a stack of
// far children (Havran's TA_B^rec order, as in pbrt's KdTreeAccel::Intersect).

#include "voxcone/accel/kdtree.h"

#include "triangle4_sse.h"
#include "voxcone/core/error.h"
#include "voxcone/core/timer.h"

#include <nlohmann/json.hpp>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <memory>

namespace voxcone {

namespace {

/// A triangle reference during the build: its bounds clipped to the node's box.
struct KdRef {
  Bounds3 box;
  uint32_t id;
};

struct KdBuildNode {
  int axis = -1;  // -1: leaf
  float split = 0.0f;
  std::vector<uint32_t> ids;  // leaf triangles
  std::unique_ptr<KdBuildNode> below, above;
};

uint32_t packets(size_t n) { return static_cast<uint32_t>((n + 3u) / 4u); }

/// Cells are entered and left at distances computed in float; a cell is skipped only when it
/// starts beyond the closest hit by more than this relative margin.
constexpr float kCellSlack = 1.0f + 1e-6f;

constexpr int kMaxDepthLimit = 60;
constexpr int kStackSize = 64;

}  // namespace

struct KdTree::Builder {
  const KdTreeBuildSettings& s;
  int maxDepth;

  std::unique_ptr<KdBuildNode> build(std::vector<KdRef> refs, const Bounds3& box, int depth, int badRefines) const {
    auto node = std::make_unique<KdBuildNode>();
    const size_t n = refs.size();
    const float leafCost = s.intersectionCost * static_cast<float>(packets(n));
    int axis = -1;
    float split = 0.0f, cost = kInf;
    if (n > 0 && depth < maxDepth) findSplit(refs, box, axis, split, cost);
    if (axis >= 0 && cost >= leafCost) {
      // Splitting costs more than a leaf: allowed for big nodes, three times in a row, as the
      // children's splits may pay for it.
      if (n <= static_cast<size_t>(s.maxLeafSize) || ++badRefines >= 3) axis = -1;
    }
    if (axis < 0) {
      node->ids.reserve(n);
      for (const KdRef& r : refs) node->ids.push_back(r.id);
      return node;
    }
    node->axis = axis;
    node->split = split;
    std::vector<KdRef> below, above;
    for (const KdRef& r : refs) {
      const float lo = r.box.lo[axis], hi = r.box.hi[axis];
      // Touching the plane from one side goes to that side; lying in it goes below.
      if (lo < split || (lo == split && hi == split)) {
        below.push_back(r);
        below.back().box.hi[axis] = std::min(hi, split);
      }
      if (hi > split) {
        above.push_back(r);
        above.back().box.lo[axis] = std::max(lo, split);
      }
    }
    std::vector<KdRef>().swap(refs);  // free this level before recursing
    Bounds3 belowBox = box, aboveBox = box;
    belowBox.hi[axis] = split;
    aboveBox.lo[axis] = split;
    if (below.size() + above.size() >= static_cast<size_t>(s.parallelThreshold)) {
      tbb::parallel_invoke([&] { node->below = build(std::move(below), belowBox, depth + 1, badRefines); },
                           [&] { node->above = build(std::move(above), aboveBox, depth + 1, badRefines); });
    } else {
      node->below = build(std::move(below), belowBox, depth + 1, badRefines);
      node->above = build(std::move(above), aboveBox, depth + 1, badRefines);
    }
    return node;
  }

  /// The plane of least SAH cost over the three axes, at the bin boundaries; axis -1 when the
  /// box is flat in every axis.
  void findSplit(const std::vector<KdRef>& refs, const Bounds3& box, int& bestAxis, float& bestSplit,
                 float& bestCost) const {
    const int bins = s.binCount;
    const float invArea = 1.0f / std::max(box.area(), 1e-30f);
    const size_t n = refs.size();
    std::array<uint32_t, 256> startHist, endHist;
    for (int axis = 0; axis < 3; ++axis) {
      const float lo = box.lo[axis], extent = box.hi[axis] - lo;
      if (!(extent > 0.0f)) continue;
      const float scale = static_cast<float>(bins) / extent;
      std::fill_n(startHist.begin(), bins, 0u);
      std::fill_n(endHist.begin(), bins, 0u);
      auto binOf = [&](float x) { return std::clamp(static_cast<int>((x - lo) * scale), 0, bins - 1); };
      for (const KdRef& r : refs) {
        ++startHist[binOf(r.box.lo[axis])];
        ++endHist[binOf(r.box.hi[axis])];
      }
      const Vec3 d = box.diagonal();
      const int o1 = (axis + 1) % 3, o2 = (axis + 2) % 3;
      const float crossArea = 2.0f * d[o1] * d[o2], ringPerLength = 2.0f * (d[o1] + d[o2]);
      size_t nBelow = 0, nAbove = n;
      for (int k = 1; k < bins; ++k) {
        // Below the plane: references starting in a lower bin; above: those not ending in one.
        nBelow += startHist[k - 1];
        nAbove -= endHist[k - 1];
        const float plane = lo + static_cast<float>(k) * (extent / static_cast<float>(bins));
        if (!(plane > lo && plane < box.hi[axis])) continue;
        const float belowArea = crossArea + ringPerLength * (plane - lo);
        const float aboveArea = crossArea + ringPerLength * (box.hi[axis] - plane);
        const float bonus = (nBelow == 0 || nAbove == 0) ? 1.0f - s.emptyBonus : 1.0f;
        const float cost = s.traversalCost + s.intersectionCost * bonus * invArea *
                                                 (belowArea * float(packets(nBelow)) + aboveArea * float(packets(nAbove)));
        if (cost < bestCost) {
          bestCost = cost;
          bestAxis = axis;
          bestSplit = plane;
        }
      }
    }
  }
};

KdTree::KdTree(const std::vector<Vec3>& positions, const std::vector<UVec3>& triangles,
               const KdTreeBuildSettings& settings, Progress* progress)
    : m_settings(settings) {
  const KdTreeBuildSettings& s = m_settings;
  if (s.binCount < 2 || s.binCount > 256) throw SettingsError("kd-tree bin count must be in [2, 256]");
  if (s.maxLeafSize < 1) throw SettingsError("kd-tree max leaf size must be at least 1");
  if (s.maxDepth < 0 || s.maxDepth > kMaxDepthLimit) throw SettingsError("kd-tree max depth must be in [0, 60]");
  Timer timer;
  if (progress) progress->start("kdtree", 1);

  std::vector<KdRef> refs;
  refs.reserve(triangles.size());
  for (uint32_t i = 0; i < triangles.size(); ++i) {
    KdRef r;
    if (!triangleBounds(positions, triangles[i], r.box)) continue;
    r.id = i;
    m_bounds.extend(r.box);
    refs.push_back(r);
  }
  m_stats.triangles = refs.size();
  if (refs.empty()) {
    m_stats.buildSeconds = timer.seconds();
    if (progress) progress->finish();
    return;
  }
  const int maxDepth =
      s.maxDepth > 0 ? s.maxDepth
                     : std::min(kMaxDepthLimit, static_cast<int>(std::lround(8.0 + 1.3 * std::log2(double(refs.size())))));
  const Builder builder{s, maxDepth};
  std::unique_ptr<KdBuildNode> root = builder.build(std::move(refs), m_bounds, 0, 0);

  // Flatten depth first: the below child follows its parent.
  const double rootArea = std::max(m_bounds.area(), 1e-30f);
  auto emit = [&](auto& self, const KdBuildNode& b, const Bounds3& box, int depth) -> uint32_t {
    const uint32_t idx = static_cast<uint32_t>(m_nodes.size());
    m_nodes.emplace_back();
    m_stats.maxDepth = std::max(m_stats.maxDepth, depth);
    const double rel = box.area() / rootArea;
    if (b.axis < 0) {
      const uint32_t first = static_cast<uint32_t>(m_tris.size());
      packTriangles(positions, triangles, b.ids.data(), static_cast<uint32_t>(b.ids.size()), m_tris);
      Node node;
      node.firstPacket = first;
      node.bits = 3u | (packets(b.ids.size()) << 2);
      m_nodes[idx] = node;
      ++m_stats.leaves;
      if (b.ids.empty()) ++m_stats.emptyLeaves;
      m_stats.references += b.ids.size();
      m_stats.sahCost += rel * s.intersectionCost * packets(b.ids.size());
      return idx;
    }
    m_stats.sahCost += rel * s.traversalCost;
    Bounds3 belowBox = box, aboveBox = box;
    belowBox.hi[b.axis] = b.split;
    aboveBox.lo[b.axis] = b.split;
    self(self, *b.below, belowBox, depth + 1);
    const uint32_t above = self(self, *b.above, aboveBox, depth + 1);
    if (above >= (1u << 30)) throw SettingsError("kd-tree: more than 2^30 nodes");
    Node node;
    node.split = b.split;
    node.bits = static_cast<uint32_t>(b.axis) | (above << 2);
    m_nodes[idx] = node;
    return idx;
  };
  emit(emit, *root, m_bounds, 1);
  root.reset();
  m_stats.nodes = m_nodes.size();
  m_stats.bytes = m_nodes.size() * sizeof(Node) + m_tris.size() * sizeof(Triangle4);
  m_stats.buildSeconds = timer.seconds();
  if (progress) progress->finish();
}

bool KdTree::clipToBounds(const Ray& ray, const float invDir[3], float tMax, float& t0, float& t1) const {
  if (m_nodes.empty()) return false;
  t0 = ray.tMin;
  t1 = tMax;
  for (int a = 0; a < 3; ++a) {
    float tNear = (m_bounds.lo[a] - ray.origin[a]) * invDir[a], tFar = (m_bounds.hi[a] - ray.origin[a]) * invDir[a];
    if (tNear > tFar) std::swap(tNear, tFar);
    // NaN (origin on a face of a flat box, direction parallel) leaves the range as it is.
    tFar *= kCellSlack;
    t0 = tNear > t0 ? tNear : t0;
    t1 = tFar < t1 ? tFar : t1;
    if (t0 > t1) return false;
  }
  return true;
}

namespace {

using sse42::anyHit;  // the kd-tree traverses with the baseline kernels only
using sse42::closerHits;
using sse42::RayTriLanes;

struct KdTodo {
  uint32_t node;
  float t0, t1;
};

}  // namespace

template <bool kAnyHit>
bool KdTree::traverse(const Ray& ray, float tMax, Hit& hit) const {
  float invDir[3];
  for (int a = 0; a < 3; ++a) invDir[a] = 1.0f / ray.dir[a];
  float t0, t1;
  if (!clipToBounds(ray, invDir, tMax, t0, t1)) return false;
  const RayTriLanes rl(ray);
  KdTodo stack[kStackSize];
  int sp = 0;
  bool found = false;
  uint32_t cur = 0;
  for (;;) {
    // Down to the next leaf along the ray, pushing the far children it also crosses.
    for (const Node* n = &m_nodes[cur]; !n->leaf(); n = &m_nodes[cur]) {
      const int a = n->axis();
      const float tPlane = (n->split - ray.origin[a]) * invDir[a];
      const bool belowFirst = ray.origin[a] < n->split || (ray.origin[a] == n->split && ray.dir[a] <= 0.0f);
      const uint32_t first = belowFirst ? cur + 1 : n->aboveChild();
      const uint32_t second = belowFirst ? n->aboveChild() : cur + 1;
      if (tPlane > t1 * kCellSlack || tPlane <= 0.0f) {
        cur = first;
      } else if (tPlane * kCellSlack < t0) {
        cur = second;
      } else {
        stack[sp++] = {second, tPlane, t1};
        cur = first;
        t1 = tPlane;
      }
    }
    const Node& leaf = m_nodes[cur];
    if (kAnyHit) {
      if (anyHit(m_tris.data() + leaf.firstPacket, leaf.packetCount(), ray, rl, tMax)) return true;
    } else {
      found |= closerHits(m_tris.data() + leaf.firstPacket, leaf.packetCount(), ray, rl, tMax, hit);
    }
    // The remaining cells lie further along the ray, nearest on top: none holds a closer hit
    // once the nearest starts beyond the closest one.
    if (sp == 0 || (!kAnyHit && stack[sp - 1].t0 > tMax * kCellSlack)) return found;
    --sp;
    cur = stack[sp].node;
    t0 = stack[sp].t0;
    t1 = stack[sp].t1;
  }
}

std::optional<Hit> KdTree::intersect(const Ray& ray) const {
  Hit hit;
  return traverse<false>(ray, ray.tMax, hit) ? std::optional<Hit>(hit) : std::nullopt;
}

bool KdTree::occluded(const Ray& ray, float tMax) const {
  Hit unused;
  return traverse<true>(ray, tMax, unused);
}

nlohmann::json KdTree::statsJson() const {
  const KdTreeStats& st = m_stats;
  return {{"kind", kind()},
          {"triangles", st.triangles},
          {"nodes", st.nodes},
          {"leaves", st.leaves},
          {"empty_leaves", st.emptyLeaves},
          {"references", st.references},
          {"references_per_triangle", st.triangles ? double(st.references) / double(st.triangles) : 0.0},
          {"max_depth", st.maxDepth},
          {"sah_cost", st.sahCost},
          {"bytes", st.bytes},
          {"build_seconds", st.buildSeconds}};
}

}  // namespace voxcone

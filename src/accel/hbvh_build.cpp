// HBVH construction: top-down binned SAH (Wald 2007, "On fast Construction of SAH-based
// Bounding Volume Hierarchies"), subtrees built in parallel with TBB, then flattened depth
// first. The tree is the same at any thread count: partitions are deterministic and subtrees
// are joined by position, not by completion order.

#include "voxcone/accel/hbvh.h"
#include "voxcone/accel/triangle.h"

#include "voxcone/core/error.h"
#include "voxcone/core/timer.h"
#include "voxcone/scene/scene.h"

#include <nlohmann/json.hpp>
#include <tbb/parallel_invoke.h>
#include <tbb/parallel_reduce.h>
#include <tbb/blocked_range.h>

#include <algorithm>
#include <array>
#include <limits>
#include <memory>
#include <new>

namespace voxcone {

namespace {

/// A triangle's bounds and centroid during the build.
struct PrimRef {
  Bounds3 box;
  Vec3 centroid;
  uint32_t id;
};

struct BuildNode {
  Bounds3 box;
  uint32_t first = 0, count = 0;  // range in the ref array (for inner nodes: of the subtree)
  std::unique_ptr<BuildNode> left, right;
  bool leaf() const { return !left; }
};

constexpr int kMaxDepth = 60;  // binary depth; the 4-wide tree is shallower, stacks hold 3 per level

class Builder {
public:
  Builder(const HbvhBuildSettings& s, Progress* p) : m_s(s), m_progress(p) {}

  std::vector<PrimRef> refs;

  std::unique_ptr<BuildNode> build(uint32_t begin, uint32_t end, int depth) {
    auto node = std::make_unique<BuildNode>();
    const auto [box, cbox] = rangeBounds(begin, end);
    node->box = box;
    node->first = begin;
    node->count = end - begin;
    const uint32_t count = end - begin;

    const float leafCost = m_s.intersectionCost * static_cast<float>(packets(count));
    int bestAxis = -1, bestSplit = -1;
    float bestCost = kInf;
    if (count > 1 && depth < kMaxDepth) findSplit(begin, end, box, cbox, bestAxis, bestSplit, bestCost);

    // Past kMaxDepth only oversized leaves are split further, at the median: the depth stays
    // below kMaxDepth + log2(triangles).
    const bool mustSplit = count > static_cast<uint32_t>(m_s.maxLeafSize);
    if (count == 1 || (!mustSplit && (depth >= kMaxDepth || leafCost <= bestCost))) {
      if (m_progress) m_progress->advance(count);
      return node;
    }
    uint32_t mid;
    if (bestAxis >= 0) {
      const int bins = m_s.binCount;
      const float lo = cbox.lo[bestAxis];
      const float scale = static_cast<float>(bins) / (cbox.hi[bestAxis] - lo);
      auto it = std::partition(refs.begin() + begin, refs.begin() + end, [&](const PrimRef& r) {
        return binOf(r.centroid[bestAxis], lo, scale, bins) < bestSplit;
      });
      mid = static_cast<uint32_t>(it - refs.begin());
    } else {
      // Every centroid coincides (or no split helps yet the leaf would be too big): split the
      // range in its middle, ordered by the largest centroid axis for a stable result.
      const int axis = maxDimension(cbox.diagonal());
      mid = begin + count / 2;
      std::nth_element(refs.begin() + begin, refs.begin() + mid, refs.begin() + end,
                       [axis](const PrimRef& a, const PrimRef& b) {
                         return a.centroid[axis] < b.centroid[axis] || (a.centroid[axis] == b.centroid[axis] && a.id < b.id);
                       });
    }
    if (mid == begin || mid == end) mid = begin + count / 2;

    if (count >= static_cast<uint32_t>(m_s.parallelThreshold)) {
      tbb::parallel_invoke([&] { node->left = build(begin, mid, depth + 1); },
                           [&] { node->right = build(mid, end, depth + 1); });
    } else {
      node->left = build(begin, mid, depth + 1);
      node->right = build(mid, end, depth + 1);
    }
    return node;
  }

private:
  /// Number of 4-triangle packets holding n triangles.
  static uint32_t packets(uint32_t n) { return (n + 3u) / 4u; }

  static int binOf(float c, float lo, float scale, int bins) {
    const int b = static_cast<int>((c - lo) * scale);
    return std::clamp(b, 0, bins - 1);
  }

  std::pair<Bounds3, Bounds3> rangeBounds(uint32_t begin, uint32_t end) const {
    using Pair = std::pair<Bounds3, Bounds3>;
    auto body = [&](const tbb::blocked_range<uint32_t>& r, Pair acc) {
      for (uint32_t i = r.begin(); i < r.end(); ++i) {
        acc.first.extend(refs[i].box);
        acc.second.extend(refs[i].centroid);
      }
      return acc;
    };
    if (end - begin < 65536u) return body(tbb::blocked_range<uint32_t>(begin, end), Pair());
    return tbb::parallel_reduce(tbb::blocked_range<uint32_t>(begin, end, 16384), Pair(), body,
                                [](Pair a, const Pair& b) {
                                  a.first.extend(b.first);
                                  a.second.extend(b.second);
                                  return a;
                                });
  }

  /// Binned SAH over the three axes: the split plane of least cost. One pass bins every
  /// primitive on all three axes; only the `binCount` bins in use are cleared (clearing all 256
  /// per node dominated the build).
  void findSplit(uint32_t begin, uint32_t end, const Bounds3& box, const Bounds3& cbox, int& bestAxis,
                 int& bestSplit, float& bestCost) const {
    const int bins = m_s.binCount;
    const float invArea = 1.0f / std::max(box.area(), 1e-30f);
    // Plain storage: Bounds3's member initializers would clear all 3 x 256 bins per call.
    struct Bin {
      Bounds3 box;
      uint32_t count;
    };
    alignas(Bin) unsigned char storage[3][256][sizeof(Bin)];
    auto bin = [&storage](int axis, int i) -> Bin& { return *reinterpret_cast<Bin*>(storage[axis][i]); };
    Vec3 scale(0.0f);
    bool splittable[3];
    for (int axis = 0; axis < 3; ++axis) {
      const float extent = cbox.hi[axis] - cbox.lo[axis];
      splittable[axis] = extent > 0.0f;
      scale[axis] = splittable[axis] ? static_cast<float>(bins) / extent : 0.0f;
      for (int i = 0; i < bins; ++i) new (storage[axis][i]) Bin{Bounds3(), 0u};
    }
    for (uint32_t i = begin; i < end; ++i) {
      const PrimRef& r = refs[i];
      for (int axis = 0; axis < 3; ++axis) {
        Bin& b = bin(axis, binOf(r.centroid[axis], cbox.lo[axis], scale[axis], bins));
        b.box.extend(r.box);
        ++b.count;
      }
    }
    for (int axis = 0; axis < 3; ++axis) {
      if (!splittable[axis]) continue;
      // Sweep from the right to get the right-hand areas, then from the left.
      std::array<float, 256> rightArea;
      std::array<uint32_t, 256> rightCount;
      Bounds3 acc;
      uint32_t n = 0;
      for (int i = bins - 1; i > 0; --i) {
        acc.extend(bin(axis, i).box);
        n += bin(axis, i).count;
        rightArea[i] = acc.area();
        rightCount[i] = n;
      }
      acc = Bounds3();
      n = 0;
      for (int i = 1; i < bins; ++i) {
        acc.extend(bin(axis, i - 1).box);
        n += bin(axis, i - 1).count;
        if (n == 0 || rightCount[i] == 0) continue;
        const float cost = m_s.traversalCost +
                           m_s.intersectionCost * invArea *
                               (acc.area() * float(packets(n)) + rightArea[i] * float(packets(rightCount[i])));
        if (cost < bestCost) {
          bestCost = cost;
          bestAxis = axis;
          bestSplit = i;
        }
      }
    }
  }


  const HbvhBuildSettings& m_s;
  Progress* m_progress;
};

}  // namespace

/// Collapses the binary build tree into 4-wide nodes: each node takes its two children and
/// repeatedly opens the inner child of largest surface area until it has four (the usual
/// BVH2 -> BVH4 collapse; Wald et al. 2008, "Getting Rid of Packets").
struct Hbvh::Flattener {
  Hbvh& bvh;
  const std::vector<PrimRef>& refs;
  const std::vector<Vec3>& pos;
  const std::vector<UVec3>& tris;
  uint64_t leaves = 0, binaryNodes = 0;
  int maxDepth = 0;

  /// SAH cost of the binary subtree, relative to the root's area.
  double sah(const BuildNode& n, float rootArea) {
    ++binaryNodes;
    const double rel = n.box.area() / rootArea;
    if (n.leaf()) return rel * bvh.m_settings.intersectionCost * ((n.count + 3u) / 4u);
    return rel * bvh.m_settings.traversalCost + sah(*n.left, rootArea) + sah(*n.right, rootArea);
  }

  uint32_t emitSubtree(const BuildNode& n, int depth) {
    const BuildNode* kids[4] = {n.left.get(), n.right.get(), nullptr, nullptr};
    int k = 2;
    while (k < 4) {
      int best = -1;
      float bestArea = -1.0f;
      for (int i = 0; i < k; ++i)
        if (!kids[i]->leaf() && kids[i]->box.area() > bestArea) {
          best = i;
          bestArea = kids[i]->box.area();
        }
      if (best < 0) break;
      const BuildNode* opened = kids[best];
      kids[best] = opened->left.get();
      kids[k++] = opened->right.get();
    }
    return emitNode(kids, k, depth);
  }

  uint32_t emitNode(const BuildNode* const* kids, int k, int depth) {
    maxDepth = std::max(maxDepth, depth);
    const uint32_t idx = static_cast<uint32_t>(bvh.m_nodes.size());
    bvh.m_nodes.emplace_back();
    Node4 node;
    for (int a = 0; a < 3; ++a)
      for (int i = 0; i < 4; ++i) {
        node.lo[a][i] = kInf;
        node.hi[a][i] = -kInf;
      }
    node.sphereBase = static_cast<uint32_t>(bvh.m_spheres.size());
    node.sphereMask = 0;
    for (int i = 0; i < 4; ++i) node.child[i] = kLeafBit;  // empty slots are never entered
    for (int i = 0; i < k; ++i) {
      for (int a = 0; a < 3; ++a) {
        node.lo[a][i] = kids[i]->box.lo[a];
        node.hi[a][i] = kids[i]->box.hi[a];
      }
      Sphere sphere;
      if (fitSphere(*kids[i], sphere)) {
        bvh.m_spheres.emplace_back(sphere.center, sphere.radius);
        node.sphereMask |= 1u << i;
      }
    }
    for (int i = 0; i < k; ++i) {
      const BuildNode& c = *kids[i];
      if (c.leaf()) {
        // Pack the leaf's triangles four to a packet; NaN vertices fill the unused lanes.
        const uint32_t first = static_cast<uint32_t>(bvh.m_tris.size());
        const uint32_t count = (c.count + 3u) / 4u;
        uint32_t ids[64];  // maxLeafSize <= 64
        for (uint32_t j = 0; j < c.count; ++j) ids[j] = refs[c.first + j].id;
        packTriangles(pos, tris, ids, c.count, bvh.m_tris);
        node.child[i] = kLeafBit | ((count - 1u) << kCountShift) | first;
        ++leaves;
      } else {
        node.child[i] = emitSubtree(c, depth + 1);
      }
    }
    bvh.m_nodes[idx] = node;
    return idx;
  }

  /// A sphere centred on the box, through the farthest vertex, when its surface area is below
  /// sphereAreaRatio times the box's. A box touched on both faces of its widest axis needs a
  /// sphere of diameter >= that extent, so most boxes are rejected before any vertex is read.
  bool fitSphere(const BuildNode& n, Sphere& out) const {
    const float ratio = bvh.m_settings.sphereAreaRatio;
    if (!(ratio > 0.0f)) return false;
    const float boxArea = n.box.area();
    const float widest = maxComponent(n.box.diagonal());
    if (kPi * widest * widest >= ratio * boxArea) return false;
    const Vec3 c = n.box.center();
    float r2 = 0.0f;
    for (uint32_t i = n.first; i < n.first + n.count; ++i) {
      const UVec3& t = tris[refs[i].id];
      for (int k = 0; k < 3; ++k) r2 = std::max(r2, glm::dot(pos[t[k]] - c, pos[t[k]] - c));
    }
    // Inflate by a relative 1e-5 so that float rounding in the sphere test never culls what
    // the box test keeps.
    out.center = c;
    out.radius = std::sqrt(r2) * (1.0f + 1e-5f) + 1e-30f;
    return out.area() < ratio * boxArea;
  }
};

nlohmann::json HbvhStats::toJson() const {
  nlohmann::json j;
  j["triangles"] = triangles;
  j["nodes"] = nodes;
  j["leaves"] = leaves;
  j["binary_nodes"] = binaryNodes;
  j["sphere_nodes"] = sphereNodes;
  j["max_depth"] = maxDepth;
  j["sah_cost"] = sahCost;
  j["avg_leaf_size"] = avgLeafSize;
  j["bytes"] = bytes;
  j["build_seconds"] = buildSeconds;
  return j;
}

Hbvh::Hbvh(const std::vector<Vec3>& positions, const std::vector<UVec3>& triangles, const HbvhBuildSettings& settings,
           Progress* progress)
    : m_settings(settings) {
  build(positions, triangles, progress);
}

Hbvh::Hbvh(const Scene& scene, const HbvhBuildSettings& settings, Progress* progress) : m_settings(settings) {
  build(scene.positions, scene.triangles, progress);
}

Bounds3 Hbvh::bounds() const {
  Bounds3 b;
  if (m_nodes.empty()) return b;
  const Node4& root = m_nodes[0];
  for (int i = 0; i < 4; ++i)
    if (root.lo[0][i] <= root.hi[0][i]) {
      b.extend(Vec3(root.lo[0][i], root.lo[1][i], root.lo[2][i]));
      b.extend(Vec3(root.hi[0][i], root.hi[1][i], root.hi[2][i]));
    }
  return b;
}

void Hbvh::build(const std::vector<Vec3>& positions, const std::vector<UVec3>& triangles, Progress* progress) {
  const HbvhBuildSettings& s = m_settings;
  if (s.binCount < 2 || s.binCount > 256) throw SettingsError("HBVH bin count must be in [2, 256]");
  static_assert((kLeafBit >> kCountShift) == 64, "packet counts 1..64 must fit between the leaf bit and the slot");
  if (s.maxLeafSize < 1 || s.maxLeafSize > 64) throw SettingsError("HBVH max leaf size must be in [1, 64]");
  if (triangles.size() > kSlotMask) throw SettingsError("HBVH: at most 2^25 - 1 triangles");  // packets < 2^25
  Timer timer;
  Builder builder(s, progress);

  // References for every triangle with finite, indexable vertices.
  builder.refs.reserve(triangles.size());
  for (uint32_t i = 0; i < triangles.size(); ++i) {
    PrimRef r;
    if (!triangleBounds(positions, triangles[i], r.box)) continue;
    r.centroid = r.box.center();
    r.id = i;
    builder.refs.push_back(r);
  }
  if (progress) progress->start("hbvh", builder.refs.size());
  m_nodes.clear();
  m_spheres.clear();
  m_tris.clear();
  m_stats = HbvhStats();
  m_stats.triangles = builder.refs.size();
  if (builder.refs.empty()) {
    if (progress) progress->finish();
    m_stats.buildSeconds = timer.seconds();
    return;
  }
  std::unique_ptr<BuildNode> root = builder.build(0, static_cast<uint32_t>(builder.refs.size()), 0);

  // Collapse to 4 children per node and flatten depth first.
  m_tris.reserve(builder.refs.size() / 2);
  Flattener flat{*this, builder.refs, positions, triangles};
  m_stats.sahCost = flat.sah(*root, std::max(root->box.area(), 1e-30f));
  if (root->leaf()) {
    // A single leaf still needs a node to hold its box.
    const BuildNode* only[1] = {root.get()};
    flat.emitNode(only, 1, 1);
  } else {
    flat.emitSubtree(*root, 1);
  }
  m_stats.nodes = m_nodes.size();
  m_stats.leaves = flat.leaves;
  m_stats.binaryNodes = flat.binaryNodes;
  m_stats.maxDepth = flat.maxDepth;
  m_stats.sphereNodes = m_spheres.size();
  m_stats.avgLeafSize = m_stats.leaves ? double(builder.refs.size()) / double(m_stats.leaves) : 0.0;
  m_stats.bytes = m_nodes.size() * sizeof(Node4) + m_spheres.size() * sizeof(Vec4) + m_tris.size() * sizeof(Triangle4);
  // Free the build tree in parallel-friendly order before timing stops.
  root.reset();
  m_stats.buildSeconds = timer.seconds();
  if (progress) progress->finish();
}

nlohmann::json Hbvh::statsJson() const {
  nlohmann::json j = m_stats.toJson();
  j["kind"] = kind();
  return j;
}

}  // namespace voxcone

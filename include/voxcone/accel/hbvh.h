#pragma once
/// \file hbvh.h
/// The hybrid bounding volume hierarchy (HBVH): a binary SAH BVH over triangles whose nodes keep
/// an AABB and, where it fits tighter, a bounding sphere; a ray must pass both to enter a node.
/// Layout as in Embree's kernels/bvh: build settings and statistics are structs of their own,
/// the split heuristic (hbvh_build.cpp), traversal (hbvh_traverse.cpp) and the primitive test
/// (triangle.h) live apart.

#include "voxcone/core/bounds.h"
#include "voxcone/core/progress.h"
#include "voxcone/core/ray.h"

#include <nlohmann/json_fwd.hpp>

#include <cstdint>
#include <optional>
#include <vector>

namespace voxcone {

class Scene;

/// Build settings (cf. Embree's RTCBuildArguments).
struct HbvhBuildSettings {
  int binCount = 16;             ///< SAH bins per axis, [2, 256]
  int maxLeafSize = 8;           ///< leaves never hold more triangles, [1, 64]
  float traversalCost = 1.0f;    ///< SAH cost of visiting a node, relative to one triangle test
  float intersectionCost = 1.0f; ///< SAH cost of one triangle test
  /// Keep a node's bounding sphere when its surface area is below this fraction of the AABB's
  /// (surface area is what decides how often a random ray enters a convex volume; Cauchy's
  /// formula). 0 disables spheres (a plain AABB BVH).
  float sphereAreaRatio = 1.0f;
  int parallelThreshold = 4096;  ///< subtrees with fewer triangles are built by one task
};

/// Statistics of a built HBVH (cf. Embree's BVHNStatistics).
struct HbvhStats {
  uint64_t triangles = 0;
  uint64_t nodes = 0;
  uint64_t leaves = 0;
  uint64_t sphereNodes = 0;   ///< nodes that keep a bounding sphere
  int maxDepth = 0;
  double sahCost = 0.0;       ///< SAH cost of the tree, relative to the root's area
  double avgLeafSize = 0.0;
  uint64_t bytes = 0;         ///< memory of nodes, spheres and triangle data
  double buildSeconds = 0.0;
  nlohmann::json toJson() const;
};

/// A ray hit: distance along the ray (units of |dir|), triangle id, barycentrics of v1 and v2.
struct Hit {
  float t = kInf;
  uint32_t triangle = 0;
  float b1 = 0.0f, b2 = 0.0f;
};

/// The hybrid BVH over a triangle soup.
class Hbvh {
public:
  /// Flat node, 32 bytes: bounds, then either the first triangle and count (leaf) or the
  /// index of the second child (interior; the first child follows the node).
  struct Node {
    Vec3 lo;
    uint32_t offset;  ///< leaf: first triangle slot; interior: index of the right child
    Vec3 hi;
    /// Bits 0-6: leaf triangle count (> 0), 0 for an interior node. Bits 7-31: index + 1 of
    /// the node's bounding sphere in the compact sphere array, 0 for none.
    uint32_t count;
    uint32_t triangleCount() const { return count & kCountMask; }
    uint32_t sphereIndexPlusOne() const { return count >> kSphereShift; }
  };
  static constexpr uint32_t kCountMask = 0x7fu;
  static constexpr uint32_t kSphereShift = 7;

  Hbvh() = default;
  /// Build over positions/triangles (world space). Triangles with non-finite or degenerate
  /// bounds are skipped.
  Hbvh(const std::vector<Vec3>& positions, const std::vector<UVec3>& triangles,
       const HbvhBuildSettings& settings = {}, Progress* progress = nullptr);
  /// Build over a scene's triangles.
  explicit Hbvh(const Scene& scene, const HbvhBuildSettings& settings = {}, Progress* progress = nullptr);

  /// Closest hit in (ray.tMin, ray.tMax), or nothing.
  std::optional<Hit> intersect(const Ray& ray) const;
  /// True when anything is hit in (ray.tMin, tMax).
  bool occluded(const Ray& ray, float tMax) const;
  bool occluded(const Ray& ray) const { return occluded(ray, ray.tMax); }

  const HbvhStats& stats() const { return m_stats; }
  const HbvhBuildSettings& settings() const { return m_settings; }
  Bounds3 bounds() const;

private:
  void build(const std::vector<Vec3>& positions, const std::vector<UVec3>& triangles, Progress* progress);

  HbvhBuildSettings m_settings;
  HbvhStats m_stats;
  std::vector<Node> m_nodes;
  std::vector<Vec4> m_spheres;      ///< centre xyz, radius w, only for nodes that keep one
  std::vector<Vec3> m_triVerts;     ///< 3 per slot, in leaf order
  std::vector<uint32_t> m_triIds;   ///< per slot: the original triangle index
};

}  // namespace voxcone

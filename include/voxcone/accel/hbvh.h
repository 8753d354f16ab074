#pragma once
/// \file hbvh.h
/// The hybrid bounding volume hierarchy (HBVH): a binned-SAH BVH over triangles whose nodes keep
/// an AABB and, where the SAH expects it to pay for its test, a bounding sphere; a ray must pass
/// both to enter a node.
/// Built binary, then collapsed to eight children per node whose boxes are tested together: with
/// one AVX2 register per plane where the CPU has it, as two SSE halves where not (the layout of
/// Embree's BVH8; the kernel is chosen at run time, so one binary runs on any x86-64). In large
/// trees the lowest nodes keep their children's boxes quantized to 8 bits a plane (QNode).
/// Layout as in Embree's kernels/bvh: build settings and statistics are structs of their own,
/// the split heuristic (hbvh_build.cpp), traversal (hbvh_traverse.cpp) and the primitive test
/// (triangle.h) live apart.

#include "voxcone/accel/accel.h"
#include "voxcone/accel/triangle.h"
#include "voxcone/core/huge_pages.h"

#include <vector>

namespace voxcone {

/// Build settings (cf. Embree's RTCBuildArguments).
struct HbvhBuildSettings {
  /// SAH bins per axis, [2, 256] (ranges of n triangles use at most 8 + n / 16). 32, as Embree's
  /// binned builder: on the dragon 16 -> 32 took the shadow rays from 10.53 to 10.28 nodes and
  /// 4.92 to 4.75 packets a ray (secondary 10.06 -> 9.95 nodes), builds within noise (dragon
  /// 0.76 -> 0.91 of Embree's time in 3 runs, 10M knot 0.98 / 0.90 -> 0.97 / 0.91); 64 no better.
  int binCount = 32;
  int maxLeafSize = 8;           ///< leaves never hold more triangles, [1, 64]
  /// SAH cost of visiting a node, relative to one leaf test (intersectionCost).
  float traversalCost = 1.0f;
  float intersectionCost = 1.0f; ///< SAH cost of one leaf test of leafTestWidth triangles
  /// Triangles the SAH counts as one leaf test (a leaf of n costs ceil(n / leafTestWidth)):
  /// the AVX2 kernel tests two 4-triangle packets in one 8-wide test. Measured on the dragon
  /// (bench/hbvh_vs_embree, 3 alternating runs, ratio to Embree): 8 instead of 4 builds in
  /// 0.80x the time (every node of up to 8 triangles a leaf without binning), 45.4 instead of
  /// 47.7 MiB, rays 1.00-1.07x as fast on AVX2 and 0.97-1.2x on SSE 4.2. The same tree on every
  /// machine whatever kernel it runs.
  int leafTestWidth = 8;
  /// Never keep a node's bounding sphere unless its surface area is below this fraction of the
  /// AABB's (surface area is what decides how often a random ray enters a convex volume;
  /// Cauchy's formula). 0 disables spheres (a plain AABB BVH).
  float sphereAreaRatio = 1.0f;
  /// SAH cost of testing a child's sphere, in the units of traversalCost: a sphere is kept only
  /// where the subtree cost it saves exceeds it (hbvh_build.cpp, fitSphere). 0 keeps every
  /// sphere below sphereAreaRatio (the earlier rule). 1 is an estimate (a scalar sphere test per
  /// child against one SIMD box test for all eight), not a measurement; the trees do not depend
  /// on it much: on the dragon, 1M and 10M knots and 2,000 scattered spheres any cost from 0.2
  /// up keeps at most one sphere (0.05: 573 on the scattered spheres), and by the area rule the
  /// spheres traced within noise of none (docs/benchmarks.md).
  float sphereTestCost = 1.0f;
  int parallelThreshold = 4096;  ///< subtrees with fewer triangles are built by one task
  /// Nodes whose subtree holds at most this many triangles keep their children's boxes
  /// quantized to 8 bits a plane relative to their own box (Hbvh::QNode: 128 bytes, two cache
  /// lines, against a full node's four), in trees over at least quantizeMinTriangles; the root
  /// is always a full node. 0 keeps every node full. A QNode costs the box test a conversion and
  /// a multiply-add a plane and saves half the node's memory traffic, which pays only where the
  /// tree outgrows the caches. Measured (bench/hbvh_vs_embree, one thread, ratio to Embree
  /// MEDIUM, medians of alternating runs, AMD Zen 5 VM): 10M-triangle knot at 0 / 64 / 512:
  /// incoherent 0.89 / 0.96 / 0.95, occlusion 0.89 / 1.02 / 0.98, primary 1.06 / 1.13 / 1.07;
  /// dragon 1.00 / 1.05 / 1.06, occlusion 1.03 / 1.06 / 1.03, primary 1.02 / 1.16 / 1.10;
  /// the bunny (0.2 MB, in L2) loses 6% on incoherent and shadow rays at 64.
  int quantizeBelow = 64;
  /// Smaller trees keep every node full. Bracketed, not measured finer: the 3.7k-triangle bunny
  /// loses with quantized nodes (above), a 100k-triangle knot (5 MB) gains (incoherent 0.97 ->
  /// 1.04, secondary 0.97 -> 1.05 at 64, two alternating runs); 2^15 triangles is where the tree
  /// (about 50 bytes a triangle, 1.6 MB) outgrows a core's 1 MB L2.
  int quantizeMinTriangles = 1 << 15;
};

/// Statistics of a built HBVH (cf. Embree's BVHNStatistics).
struct HbvhStats {
  uint64_t triangles = 0;
  uint64_t nodes = 0;         ///< 8-wide nodes
  uint64_t leaves = 0;
  uint64_t binaryNodes = 0;   ///< nodes of the binary tree before the collapse
  uint64_t quantizedNodes = 0;  ///< of nodes, those with quantized child boxes (Hbvh::QNode)
  uint64_t sphereNodes = 0;   ///< children (inner or leaf) that keep a bounding sphere
  int maxDepth = 0;           ///< of the 8-wide tree, the root at depth 1
  double sahCost = 0.0;       ///< SAH cost of the binary tree, relative to the root's area
  double avgLeafSize = 0.0;
  uint64_t bytes = 0;         ///< memory of nodes, spheres and triangle data
  /// Every stored child box reaches at least this far beyond its triangles' bounds:
  /// Hbvh::kBoxPaddingRelative of the largest coordinate magnitude (0 in scenes beyond 2^26).
  float boxPadding = 0.0f;
  /// Rays whose origin components are at most this in magnitude take the padded box test (one
  /// FMA a plane, Embree's form, conservative thanks to the padding); others the robust one
  /// (Ize's). -1: none. hbvh_build.cpp, paddedOriginBound, derives it.
  float paddedOriginBound = -1.0f;
  double buildSeconds = 0.0;
  nlohmann::json toJson() const;
};

/// How a built HBVH lies in memory (Hbvh::layout: a walk over the arrays, apart from the code
/// that wrote them).
struct HbvhLayout {
  uint64_t nodes = 0, qnodes = 0, leaves = 0;
  uint64_t leavesBelowQNodes = 0;      ///< leaf children of QNodes
  uint64_t leavesAfterTheirQNode = 0;  ///< of those, the ones laid out after their QNode, in child order
  uint64_t outOfBounds = 0;            ///< references past the end of their array
  /// Triangles in the leaves, and the distinct vertex positions of each leaf summed over them,
  /// with the leaves that have more than 16 (what a leaf storing each vertex once would hold; such
  /// a format, ef5d4fb, saved 30% of the memory and no time: docs/benchmarks.md).
  uint64_t leafTriangles = 0, leafDistinctVertices = 0, leavesOver16Vertices = 0;
};

/// The hybrid BVH over a triangle soup. With sphereAreaRatio 0 it is a plain AABB BVH (kind
/// "bvh"): the same SAH build, layout and traversal, no spheres.
class Hbvh final : public Accel {
public:
  static constexpr int kWidth = 8;  ///< children per node
  /// The stored boxes' padding, relative to the scene's largest coordinate magnitude P (plus
  /// 2^-68): it lets rays from origins within 4.8 P take the one-FMA box test (HbvhStats::
  /// paddedOriginBound). 2^-16 (24 P) made the 10M knot's incoherent rays test 1.40 leaves
  /// instead of 1.35 unpadded; 2^-18 1.36.
  static constexpr double kBoxPaddingRelative = 0x1p-18;

  /// 8-wide node, 256 bytes: the children's boxes side by side (one AVX register, or two SSE
  /// registers, per plane).
  struct alignas(64) Node {
    float lo[3][kWidth];     ///< [axis][child]; an empty slot has lo = +inf, hi = -inf
    float hi[3][kWidth];
    /// A Node's slot, kQuantBit | a QNode's line, or kLeafBit | (packets - 1) << kCountShift | first unit
    uint32_t child[kWidth];
    uint32_t sphereBase;     ///< index in m_spheres of this node's first child sphere
    uint32_t sphereMask;     ///< bit i: child i keeps a sphere (stored in child order)
  };
  /// 8-wide node with quantized child boxes, 128 bytes: child i's box on axis a is
  /// [origin[a] + lo[a][i] scale[a], origin[a] + hi[a][i] scale[a]], each computed in float as
  /// written (scale a power of two, so the product is exact and only the sum rounds); the build
  /// chooses lo and hi so that those floats contain the child's box. The child references share
  /// the first line with origin and scale, which the box test reads with the planes (second
  /// line), so both lines are loaded at once.
  struct alignas(64) QNode {
    uint32_t child[kWidth];  ///< as Node::child
    float origin[3];
    float scale[3];
    uint32_t sphereBase;     ///< as Node's
    uint32_t sphereMask;
    uint8_t lo[3][kWidth];
    uint8_t hi[3][kWidth];
    uint32_t used;           ///< mask of the slots that hold a child (the others are never entered)
    uint32_t pad[3];
  };
  /// Nodes are stored in 128-byte slots, a Node in two (m_nodes).
  struct alignas(64) NodeSlot {
    unsigned char bytes[128];
  };
  static_assert(sizeof(Node) == 2 * sizeof(NodeSlot), "node sizes");
  /// The block store (m_blocks) holds QNodes and leaves in 32-byte units, each QNode from a
  /// line of its own and followed by its leaves (about 1.5 KB together), so that a ray finds the
  /// leaves it tests in its QNode's 4 KiB page more often than not, and the full Nodes, alone in
  /// m_nodes, stay within fewer pages. On a virtual machine whose host maps 4 KiB pages a
  /// translation that misses the TLB costs about as much as a line from DRAM (bench/page_walk),
  /// whatever the guest's page size.
  struct alignas(64) BlockLine {
    unsigned char bytes[64];
    BlockLine() {}  // sized first, filled in parallel: no zeroing
  };
  static constexpr uint32_t kUnitBytes = 32;
  static_assert(sizeof(QNode) == 2 * sizeof(BlockLine), "a QNode is two lines");
  static constexpr uint32_t kLeafBit = 0x80000000u;
  /// A node reference with this bit is a QNode's (its line in m_blocks below); without, a
  /// Node's (its slot in m_nodes).
  static constexpr uint32_t kQuantBit = 0x40000000u;
  static constexpr uint32_t kCountShift = 27;  ///< leaves hold up to 16 packets (64 triangles)
  static constexpr uint32_t kSlotMask = (1u << kCountShift) - 1u;  ///< a leaf's first unit
  /// A leaf packet's storage (160 bytes, five units in m_blocks): a leaf's packets in pairs,
  /// each row of a pair (a coordinate of eight triangles) eight consecutive floats, so that the
  /// AVX2 test loads it in one instruction, then the ids; an odd last packet as a Triangle4
  /// (four floats a row). Floats only, ids by their bits.
  struct alignas(32) LeafUnit {
    float f[40];
  };
  static_assert(sizeof(LeafUnit) % kUnitBytes == 0, "packets are whole units");
  /// A packet's rows: [vertex][axis] at row 3 vertex + axis, then the ids (kIdRow); a pair's
  /// rows are kPairStride floats, a single packet's kSingleStride (LeafUnit: 10 rows of 4).
  static constexpr int kIdRow = 9, kLeafRows = 10, kPairStride = 8, kSingleStride = 4;
  static_assert(sizeof(LeafUnit) == kLeafRows * kSingleStride * sizeof(float), "a leaf unit is one packet");


  Hbvh() = default;
  /// Build over positions/triangles (world space). Triangles with non-finite or degenerate
  /// bounds are skipped.
  Hbvh(const std::vector<Vec3>& positions, const std::vector<UVec3>& triangles,
       const HbvhBuildSettings& settings = {}, Progress* progress = nullptr);
  /// Build over a scene's triangles.
  explicit Hbvh(const Scene& scene, const HbvhBuildSettings& settings = {}, Progress* progress = nullptr);

  /// Both queries trace a ray with tMin < 0 (or -0) from its origin (tMin +0), as Embree does
  /// tnear: the kernels order box distances as integers, which needs them from +0 on.
  std::optional<Hit> intersect(const Ray& ray) const override;
  bool occluded(const Ray& ray, float tMax) const override;
  using Accel::occluded;
  Bounds3 bounds() const override;
  std::string kind() const override { return m_settings.sphereAreaRatio > 0.0f ? "hbvh" : "bvh"; }
  uint64_t bytes() const override { return m_stats.bytes; }
  double buildSeconds() const override { return m_stats.buildSeconds; }
  nlohmann::json statsJson() const override;

  const HbvhStats& stats() const { return m_stats; }
  /// Walk the tree and check its block layout (each QNode's leaves follow it, in child order);
  /// count the leaves' distinct vertices.
  HbvhLayout layout() const;
  const HbvhBuildSettings& settings() const { return m_settings; }

  /// The traversal kernels: SSE 4.2 (any x86-64 this project targets), AVX2 (8 boxes in one
  /// register) or AVX-512 (AVX2's with mask registers and compress). All find the same hits,
  /// bit for bit (the triangle test runs the same operations everywhere, the box tests are
  /// conservative and ties go to the smaller triangle id); the wider are only faster.
  enum class Simd { Sse42, Avx2, Avx512 };
  /// The best kernel this CPU runs; VOXCONE_SIMD=sse4.2 (or avx2) in the environment forces a
  /// narrower one.
  static Simd hostSimd();
  /// Every kernel this CPU and this build run, narrowest first (tests run them all).
  static std::vector<Simd> runnableSimds();
  static const char* simdName(Simd simd);
  /// Choose the kernel; SettingsError when the CPU (or the build) lacks it.
  void setSimd(Simd simd);
  Simd simd() const { return m_simd; }

private:
  void build(const std::vector<Vec3>& positions, const std::vector<UVec3>& triangles, Progress* progress);
  struct Flattener;  ///< collapses the binary build tree into Nodes (hbvh_build.cpp)

  HbvhBuildSettings m_settings;
  HbvhStats m_stats;
  Simd m_simd = hostSimd();
  Bounds3 m_bounds;  ///< of the triangles (the stored boxes are padded)
  std::vector<NodeSlot, HugePageAllocator<NodeSlot>> m_nodes;  ///< the Nodes, depth first, the root at slot 0
  std::vector<Vec4> m_spheres;      ///< centre xyz, radius w, only for children that keep one
  /// QNodes and leaves (BlockLine), depth first: a node's leaves, then its inner children's parts.
  std::vector<BlockLine, HugePageAllocator<BlockLine>> m_blocks;
};

}  // namespace voxcone

// HBVH construction: the binary SAH tree (hbvh_binned_sah.cpp) collapsed into 8-wide nodes with
// bounding spheres where the SAH expects them to pay, quantized where they are small, and laid
// out depth first (Hbvh::Flattener); the build's statistics.

#include "voxcone/accel/hbvh.h"
#include "hbvh_build_types.h"
#include "voxcone/accel/triangle.h"

#include "voxcone/core/error.h"
#include "voxcone/core/huge_pages.h"
#include "voxcone/core/timer.h"
#include "voxcone/scene/scene.h"

#include <nlohmann/json.hpp>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/parallel_reduce.h>
#include <tbb/blocked_range.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <new>
#include <optional>
#include <type_traits>
#include <utility>
#include <vector>

#include <smmintrin.h>

namespace voxcone {

using namespace hbvh_build;

/// Collapses the binary build tree into 8-wide nodes: each node takes its two children and
/// repeatedly opens the inner child of largest surface area until it has eight (the usual
/// BVH2 -> BVHN collapse; Wald et al. 2008, "Getting Rid of Packets"; Embree's BVH8), laid out
/// depth first.
/// Two passes: `measure` counts every collapsed subtree's nodes, packets and spheres (bottom
/// up, in parallel) into the binary node it is collapsed from, so that `fill` can give each
/// subtree its ranges of the arrays up front and write subtrees in parallel; the layout is the
/// serial depth-first one, at any thread count. Both passes collapse a node the same way
/// (`collapse`); nothing else is allocated.
struct Hbvh::Flattener {
  Hbvh& bvh;
  const std::vector<uint32_t>& ids;  ///< the triangle of each reference, in the binary tree's order
  const std::vector<Vec3>& pos;
  const std::vector<UVec3>& tris;
  float pad;  ///< every stored child box reaches at least this far beyond its triangles (HbvhStats::boxPadding)
  /// The largest magnitude of a stored plane (of a QNode: origin + q scale, as a real number),
  /// as float bits, made by fill.
  std::atomic<uint32_t> planeBound{0};

  /// The children of the 8-wide node collapsed from inner node n (a lone leaf is the root's
  /// only child); returns how many.
  static int collapse(const BuildNode& n, const BuildNode* kids[kWidth]) {
    if (n.leaf()) {
      kids[0] = &n;
      return 1;
    }
    kids[0] = &n.kids[0];
    kids[1] = &n.kids[1];
    int k = 2;
    while (k < kWidth) {
      int best = -1;
      float bestArea = -1.0f;
      for (int i = 0; i < k; ++i)
        if (!kids[i]->leaf() && kids[i]->area > bestArea) {
          best = i;
          bestArea = kids[i]->area;
        }
      if (best < 0) break;
      const BuildNode* opened = kids[best];
      kids[best] = &opened->kids[0];
      kids[k++] = &opened->kids[1];
    }
    return k;
  }

  /// Write the leaf of triangles leafIds[0..count) from `out` (Hbvh::LeafUnit's layout): pairs of
  /// packets eight lanes to a row, an odd last packet four; NaN vertices and id 0 in unused lanes
  /// (read by closerHitsLeaf / anyHitLeaf in hbvh_traverse_kernel.h).
  void packLeaf(const uint32_t* leafIds, uint32_t count, float* out) const {
    const uint32_t packets = (count + 3u) / 4u;
    const auto put = [&](float* block, int stride, uint32_t first) {
      for (int lane = 0; lane < stride; ++lane) {
        const bool used = first + lane < count;
        const uint32_t id = used ? leafIds[first + lane] : 0u;
        std::memcpy(block + kIdRow * stride + lane, &id, sizeof id);
        for (int vtx = 0; vtx < 3; ++vtx) {
          const Vec3 v = used ? pos[tris[id][vtx]] : Vec3(std::numeric_limits<float>::quiet_NaN());
          for (int a = 0; a < 3; ++a) block[(3 * vtx + a) * stride + lane] = v[a];
        }
      }
    };
    uint32_t first = 0;
    for (uint32_t p = 1; p < packets; p += 2, first += kPairStride, out += kLeafRows * kPairStride)
      put(out, kPairStride, first);
    if (packets & 1u) put(out, kSingleStride, first);
  }
  static constexpr uint32_t kQNodeUnits = sizeof(QNode) / kUnitBytes;
  static constexpr uint32_t kLineUnits = sizeof(BlockLine) / kUnitBytes;
  static constexpr uint32_t kPacketUnits = sizeof(LeafUnit) / kUnitBytes;
  /// Block units of leaf n's packets.
  static uint32_t leafUnits(const BuildNode& n) { return (n.count + 3u) / 4u * kPacketUnits; }
  static uint64_t roundToLine(uint64_t units) { return (units + kLineUnits - 1) / kLineUnits * kLineUnits; }

  /// Subtrees of more triangles than the build's parallel threshold are measured and filled
  /// as parallel tasks.
  uint32_t parallelFill() const { return uint32_t(bvh.m_settings.parallelThreshold); }

  /// SAH cost of the binary subtree, relative to the root's area; counts binary nodes and leaves.
  double sah(const BuildNode& n, float rootArea, uint64_t& binaryNodes, uint64_t& leaves) const {
    ++binaryNodes;
    const double rel = n.area / rootArea;
    if (n.leaf()) {
      ++leaves;
      return rel * bvh.m_settings.intersectionCost * ((n.count + 3u) / 4u);
    }
    return rel * bvh.m_settings.traversalCost + sah(n.kids[0], rootArea, binaryNodes, leaves) +
           sah(n.kids[1], rootArea, binaryNodes, leaves);
  }

  /// Whether the 8-wide node collapsed from n (not the root) is a QNode: in a tree of at least
  /// quantizeMinTriangles, a subtree of at most quantizeBelow triangles whose box's 255th part
  /// stays finite in powers of two.
  bool quantized(const BuildNode& n) const {
    const HbvhBuildSettings& s = bvh.m_settings;
    return ids.size() >= size_t(s.quantizeMinTriangles) && n.count <= uint32_t(s.quantizeBelow) &&
           maxComponent(n.box.diagonal()) < 0x1p100f;
  }

  /// Measure the collapse of inner node n (or of a lone leaf as the root's only child) into
  /// n's wide counts, n written as a QNode where `quant`; returns its depth in 8-wide levels and
  /// counts the QNodes.
  int measure(BuildNode& n, bool quant, std::atomic<uint64_t>& qnodes) {
    const BuildNode* kids[kWidth];
    const int k = collapse(n, kids);
    int depths[kWidth] = {};
    // Kids are subtrees of n: measuring one writes only its own nodes.
    auto sub = [&](int i) {
      if (!kids[i]->leaf()) depths[i] = measure(*const_cast<BuildNode*>(kids[i]), quantized(*kids[i]), qnodes);
    };
    if (n.count > parallelFill()) tbb::parallel_for(0, k, sub);
    else
      for (int i = 0; i < k; ++i) sub(i);
    // The layout fill writes: the node (a Node in m_nodes, a QNode in m_blocks), its leaves'
    // units, padding to a line, its inner kids' parts (each whole lines).
    n.wideNodes = quant ? 0 : 2;
    if (quant) ++qnodes;
    uint64_t units = quant ? kQNodeUnits : 0;
    for (int i = 0; i < k; ++i)
      if (kids[i]->leaf()) units += leafUnits(*kids[i]);
    units = roundToLine(units);
    n.wideSpheres = 0;
    int depth = 0;
    for (int i = 0; i < k; ++i) {
      Sphere sphere;
      if (fitSphere(*kids[i], sphere)) ++n.wideSpheres;
      if (!kids[i]->leaf()) {
        n.wideNodes += kids[i]->wideNodes;
        n.wideSpheres += kids[i]->wideSpheres;
        units += kids[i]->wideUnits;
        depth = std::max(depth, depths[i]);
      }
    }
    // 2^32 units are 128 GiB: build() refuses far less (leaf references hold 2^27 units).
    n.wideUnits = uint32_t(std::min<uint64_t>(units, UINT32_MAX - 1u));
    return depth + 1;
  }

  /// x moved outwards by at least `pad`: down (lo) or up (hi), rounded outwards.
  static float padOut(float x, float pad, bool up) {
    if (pad == 0.0f || !std::isfinite(x)) return x;
    const double y = up ? double(x) + pad : double(x) - pad;
    float f = float(y);
    if (up ? double(f) < y : double(f) > y) f = std::nextafter(f, up ? kInf : -kInf);
    return f;
  }
  Bounds3 padded(const Bounds3& b) const {
    Bounds3 out;
    for (int a = 0; a < 3; ++a) {
      out.lo[a] = padOut(b.lo[a], pad, false);
      out.hi[a] = padOut(b.hi[a], pad, true);
    }
    return out;
  }
  void notePlanes(double magnitude) {
    const float f = float(magnitude) * (1.0f + 0x1p-20f);  // rounded up, with room
    uint32_t bits;
    std::memcpy(&bits, &f, sizeof bits);
    uint32_t seen = planeBound.load(std::memory_order_relaxed);
    while (bits > seen && !planeBound.compare_exchange_weak(seen, bits, std::memory_order_relaxed)) {
    }
  }

  /// The float the traversal computes for quantized plane q (enterBoxesQ): origin + q scale.
  static float dequantize(float origin, float scale, int q) {
    const float offset = float(q) * scale;  // exact: scale is a power of two
    return origin + offset;
  }
  /// Quantize the kids' boxes into `out` relative to their union, each plane rounded outwards
  /// so that the floats the traversal makes contain the kid's box (checked as it computes them).
  static void quantize(const Bounds3* kids, int k, QNode& out) {
    Bounds3 box;
    for (int i = 0; i < k; ++i) box.extend(kids[i]);
    for (int a = 0; a < 3; ++a) {
      const float lo = box.lo[a], hi = box.hi[a];
      // The smallest power of two whose 255 steps from lo reach hi, as the traversal adds.
      int e;
      std::frexp(std::max((hi - lo) / 255.0f, std::numeric_limits<float>::min()), &e);
      float scale = std::ldexp(1.0f, e - 1);
      while (dequantize(lo, scale, 255) < hi) scale *= 2.0f;
      out.origin[a] = lo;
      out.scale[a] = scale;
      for (int i = 0; i < kWidth; ++i) {
        int qlo = 255, qhi = 0;  // an empty slot (masked by `used` anyway)
        if (i < k) {
          const float cl = kids[i].lo[a], ch = kids[i].hi[a];
          qlo = int(std::clamp(std::floor((cl - lo) / scale), 0.0f, 255.0f));
          while (qlo > 0 && dequantize(lo, scale, qlo) > cl) --qlo;
          while (qlo < 255 && dequantize(lo, scale, qlo + 1) <= cl) ++qlo;
          qhi = int(std::clamp(std::ceil((ch - lo) / scale), float(qlo), 255.0f));
          while (qhi < 255 && dequantize(lo, scale, qhi) < ch) ++qhi;
          while (qhi > qlo && dequantize(lo, scale, qhi - 1) >= ch) --qhi;
        }
        out.lo[a][i] = uint8_t(qlo);
        out.hi[a][i] = uint8_t(qhi);
      }
    }
    out.used = (1u << k) - 1u;
    out.pad[0] = out.pad[1] = out.pad[2] = 0;
  }

  /// Write the collapse of n: a Node at slot `node`, or where `quant` a QNode at block unit
  /// `unit` (a line's first); its kids' spheres from `sphere`; its leaves' packets from `unit`
  /// (after the QNode), and its inner kids' parts after them, in kid order, each from a line
  /// (measure's layout: depth first in both arrays; spheres of this node's kids, then the
  /// subtrees').
  void fill(const BuildNode& n, uint32_t node, uint32_t sphere, uint32_t unit, bool quant) {
    const BuildNode* kids[kWidth];
    const int k = collapse(n, kids);
    Node out;
    QNode qout;
    Bounds3 boxes[kWidth];
    for (int i = 0; i < k; ++i) boxes[i] = padded(kids[i]->box);
    double planes = 0.0;
    if (quant) {
      quantize(boxes, k, qout);
      for (int a = 0; a < 3; ++a) {
        const double origin = qout.origin[a];
        planes = std::max({planes, std::fabs(origin), std::fabs(origin + 255.0 * double(qout.scale[a]))});
      }
    } else {
      for (int a = 0; a < 3; ++a)
        for (int i = 0; i < kWidth; ++i) {
          out.lo[a][i] = i < k ? boxes[i].lo[a] : kInf;  // an empty slot is never entered
          out.hi[a][i] = i < k ? boxes[i].hi[a] : -kInf;
          if (i < k) planes = std::max({planes, std::fabs(double(out.lo[a][i])), std::fabs(double(out.hi[a][i]))});
        }
    }
    notePlanes(planes);
    uint32_t sphereMask = 0;
    const uint32_t sphereBase = sphere;
    for (int i = 0; i < k; ++i) {
      Sphere s;
      if (fitSphere(*kids[i], s)) {
        sphereMask |= 1u << i;
        bvh.m_spheres[sphere++] = Vec4(s.center, s.radius);
      }
    }
    uint32_t child[kWidth];
    for (int i = 0; i < kWidth; ++i) child[i] = kLeafBit;  // empty slots are never entered
    // Where each kid's part starts: the leaves' packets, then from a line the inner kids'.
    const uint32_t self = unit;
    uint32_t nextNode = node + (quant ? 0 : 2);
    unit += quant ? kQNodeUnits : 0;
    uint32_t starts[kWidth][3];  // node, sphere, unit
    for (int i = 0; i < k; ++i)
      if (kids[i]->leaf()) {
        child[i] = kLeafBit | ((kids[i]->count + 3u) / 4u - 1u) << kCountShift | unit;
        starts[i][2] = unit;
        unit += leafUnits(*kids[i]);
      }
    unit = uint32_t(roundToLine(unit));
    for (int i = 0; i < k; ++i)
      if (!kids[i]->leaf()) {
        const bool q = quantized(*kids[i]);
        child[i] = q ? kQuantBit | unit / kLineUnits : nextNode;
        starts[i][0] = nextNode;
        starts[i][1] = sphere;
        starts[i][2] = unit;
        nextNode += kids[i]->wideNodes;
        sphere += kids[i]->wideSpheres;
        unit += kids[i]->wideUnits;
      }
    const auto write = [&](auto& made, void* at) {  // a Node or a QNode, into its place
      std::copy(child, child + kWidth, made.child);
      made.sphereBase = sphereBase;
      made.sphereMask = sphereMask;
      new (at) std::decay_t<decltype(made)>(made);
    };
    if (quant) write(qout, bvh.m_blocks.data() + self / kLineUnits);
    else write(out, bvh.m_nodes.data() + node);
    auto kid = [&](int i) {
      const BuildNode& b = *kids[i];
      if (b.leaf()) {
        unsigned char* at = reinterpret_cast<unsigned char*>(bvh.m_blocks.data()) + size_t(starts[i][2]) * kUnitBytes;
        packLeaf(ids.data() + b.first, b.count, reinterpret_cast<float*>(at));
      } else {
        fill(b, starts[i][0], starts[i][1], starts[i][2], quantized(b));
      }
    };
    if (n.count > parallelFill()) tbb::parallel_for(0, k, kid);
    else
      for (int i = 0; i < k; ++i) kid(i);
  }

  /// The farthest vertex of a leaf from its box's centre.
  float leafReach(const BuildNode& n) const {
    const Vec3 c = n.box.center();
    float r2 = 0.0f;
    for (uint32_t i = n.first; i < n.first + n.count; ++i) {
      const UVec3& t = tris[ids[i]];
      for (int k = 0; k < 3; ++k) r2 = std::max(r2, glm::dot(pos[t[k]] - c, pos[t[k]] - c));
    }
    return std::sqrt(r2);
  }
  /// n's reach (BuildNode::reach), made on first use. Above the leaves: the larger over the two
  /// children of a bound on the distance from n's box centre to the child's vertices, the
  /// child's own reach from its centre or its box's farthest corner, whichever is less. Called
  /// for a subtree only once no other task works in it (measure's kids are measured first), and
  /// by fill on what measure made.
  float reachOf(const BuildNode& n) const {
    if (n.reach != BuildNode::kReachUnknown) return n.reach;
    float r;
    if (n.leaf()) {
      r = leafReach(n);
    } else {
      const Vec3 c = n.box.center();
      r = 0.0f;
      for (int i = 0; i < 2; ++i) {
        const BuildNode& child = n.kids[i];
        const float corner = glm::length(glm::max(glm::abs(child.box.lo - c), glm::abs(child.box.hi - c)));
        const float centre = glm::length(child.box.center() - c);
        r = std::max(r, std::min(centre + reachOf(child), corner));
      }
    }
    n.reach = r;
    return r;
  }

  /// A sphere centred on the box, of radius the subtree's reach (BuildNode::reach: the farthest
  /// vertex at a leaf, a bound from the children's above), kept where the SAH expects it to pay:
  /// a ray that reaches the child's box then also tests the sphere (sphereTestCost) and enters
  /// the subtree (its cost) only when it passes both, about as often as the smaller of the two
  /// areas says (Cauchy's formula), so the sphere pays when
  ///   (A_box - A_sphere) cost > A_box sphereTestCost,
  /// and never where its area is not below sphereAreaRatio times the box's. A box touched on
  /// both faces of its widest axis needs a sphere of diameter >= that extent, so most boxes are
  /// rejected at once (and their reach never made).
  bool fitSphere(const BuildNode& n, Sphere& out) const {
    const HbvhBuildSettings& s = bvh.m_settings;
    float ratio = s.sphereAreaRatio;
    if (s.sphereTestCost > 0.0f) ratio = std::min(ratio, 1.0f - s.sphereTestCost / std::max(n.cost, 1e-30f));
    if (!(ratio > 0.0f)) return false;
    const float boxArea = n.area;
    const float widest = maxComponent(n.box.diagonal());
    if (kPi * widest * widest >= ratio * boxArea) return false;
    // Inflate by a relative 1e-5 so that float rounding in the sphere test never culls what
    // the box test keeps.
    out.center = n.box.center();
    out.radius = reachOf(n) * (1.0f + 1e-5f) + 1e-30f;
    return out.area() < ratio * boxArea;
  }
};

namespace {

/// The largest origin component magnitude L for which the padded box test
/// (hbvh_traverse_kernel.h, PaddedBoxRay) is conservative in a tree whose boxes are padded by at
/// least `pad` and whose stored planes are at most `planes` in magnitude (P), or -1 for none.
/// With u = 2^-24, 1/d = fl(1/d) (a normal float: the kernel admits |d| <= 2^64 only) and
/// K = fl(-o (1/d)), a full node's slab distance fl(p (1/d) + K) (one FMA; a product and a sum in
/// SSE) differs from the exact (p - o) / d by at most u (3 P + 3 L) / |d| (terms to second order
/// in u folded in with room to spare: the relative errors of 1/d and of the final rounding,
/// (2 + u) u |p - o| / |d|, that of K, (1 + u)^2 u |o| / |d|, and SSE's product's, (1 + u)^2 u
/// |p| / |d|). A QNode's, fl(q fl(scale (1/d)) + fl(origin (1/d) + K)) with scale (1/d) exact (a
/// power of two), by at most u (7 P + 4 L) / |d|: the same terms, the offset's rounding
/// u |origin - o| / |d| and in SSE two more products' (u 3 P / |d|), and the real plane
/// origin + q scale lying within u P of the float the build checked. So, in space, the error is
/// at most u (8 P + 5 L), plus 2^-70 for roundings that underflow (2^-150 each in t, a QNode's
/// scale (1/d) times q <= 255, times |d| <= 2^64: under 2^-75). A box padded by twice that or
/// more is entered by every ray that enters the unpadded box (the entry distances come out no
/// later and the exit ones no earlier than the exact ones; a zero direction component becomes
/// 1e-30 and such a ray's slab on that axis extends at least pad 1e30 / |d|: the kernel requires
/// the largest component >= 2^-40). The factor two leaves room for the watertight test's own
/// rounding (a hit's t may lie a little before the exact one; tested, not proven:
/// Hbvh.PaddedAndRobustBoxTestsFindTheBruteForceHits).
/// Products stay finite (1/d <= 1e30, P and L <= 2^26).
float paddedOriginBound(double pad, double planes) {
  constexpr double u = 0x1p-24, limit = 0x1p26;
  if (!(pad > 0.0) || !(planes <= limit)) return -1.0f;
  const double bound = (pad / 2.0 - 0x1p-70 - 8.0 * u * planes) / (5.0 * u);
  if (!(bound > 0.0)) return -1.0f;
  const float f = float(std::min(bound, limit));
  return double(f) <= bound ? f : std::nextafter(f, 0.0f);
}

}  // namespace

nlohmann::json HbvhStats::toJson() const {
  nlohmann::json j;
  j["triangles"] = triangles;
  j["nodes"] = nodes;
  j["leaves"] = leaves;
  j["binary_nodes"] = binaryNodes;
  j["quantized_nodes"] = quantizedNodes;
  j["sphere_nodes"] = sphereNodes;
  j["max_depth"] = maxDepth;
  j["sah_cost"] = sahCost;
  j["avg_leaf_size"] = avgLeafSize;
  j["bytes"] = bytes;
  j["box_padding"] = boxPadding;
  j["padded_origin_bound"] = paddedOriginBound;
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
  return m_bounds;
}

HbvhLayout Hbvh::layout() const {
  HbvhLayout out;
  if (m_nodes.empty()) return out;
  using F = Flattener;  // the unit sizes fill laid the blocks out with
  const uint64_t lineCount = m_blocks.size(), unitCount = lineCount * F::kLineUnits;
  // A leaf's triangles (lanes whose first x is not the padding's NaN) and distinct vertices.
  std::vector<std::array<uint32_t, 3>> vertices;
  const auto countVertices = [&](uint64_t firstUnit, uint32_t packets) {
    const float* block = reinterpret_cast<const float*>(reinterpret_cast<const unsigned char*>(m_blocks.data()) +
                                                        firstUnit * kUnitBytes);
    vertices.clear();
    for (uint32_t p = 0; p < packets;) {
      const int stride = packets - p >= 2 ? kPairStride : kSingleStride;
      for (int lane = 0; lane < stride; ++lane) {
        if (std::isnan(block[lane])) continue;
        ++out.leafTriangles;
        for (int vtx = 0; vtx < 3; ++vtx) {
          std::array<uint32_t, 3> bits;
          for (int a = 0; a < 3; ++a) std::memcpy(&bits[a], block + (3 * vtx + a) * stride + lane, sizeof(float));
          vertices.push_back(bits);
        }
      }
      block += kLeafRows * stride;
      p += stride / kSingleStride;
    }
    std::sort(vertices.begin(), vertices.end());
    const uint64_t distinct = uint64_t(std::unique(vertices.begin(), vertices.end()) - vertices.begin());
    out.leafDistinctVertices += distinct;
    out.leavesOver16Vertices += distinct > 16;
  };
  std::vector<uint32_t> stack = {0};
  while (!stack.empty()) {
    const uint32_t ref = stack.back();
    stack.pop_back();
    const bool quant = ref & kQuantBit;
    const uint32_t index = ref & ~kQuantBit;
    if (quant ? index + 1 >= lineCount : index + 1 >= m_nodes.size()) {
      ++out.outOfBounds;
      continue;
    }
    const uint32_t* child;
    uint32_t used = 0;
    if (quant) {
      const QNode& q = *reinterpret_cast<const QNode*>(m_blocks.data() + index);
      child = q.child;
      used = q.used;
      ++out.qnodes;
    } else {
      const Node& n = *reinterpret_cast<const Node*>(m_nodes.data() + index);
      child = n.child;
      for (int i = 0; i < kWidth; ++i) used |= uint32_t(n.lo[0][i] <= n.hi[0][i]) << i;
      ++out.nodes;
    }
    uint64_t expected = uint64_t(index) * F::kLineUnits + F::kQNodeUnits;  // after a QNode
    bool inOrder = true;
    for (int i = 0; i < kWidth; ++i) {
      if (!(used >> i & 1u)) continue;
      const uint32_t c = child[i];
      if (!(c & kLeafBit)) {
        stack.push_back(c);
        continue;
      }
      ++out.leaves;
      const uint32_t packets = ((c & ~kLeafBit) >> kCountShift) + 1u;
      const uint64_t first = c & kSlotMask, units = uint64_t(packets) * F::kPacketUnits;
      if (first + units > unitCount) ++out.outOfBounds;
      else countVertices(first, packets);
      if (!quant) continue;
      ++out.leavesBelowQNodes;
      inOrder = inOrder && first == expected;
      out.leavesAfterTheirQNode += inOrder;
      expected = first + units;
    }
  }
  return out;
}

void Hbvh::build(const std::vector<Vec3>& positions, const std::vector<UVec3>& triangles, Progress* progress) {
  const HbvhBuildSettings& s = m_settings;
  if (s.binCount < 2 || s.binCount > 256) throw SettingsError("HBVH bin count must be in [2, 256]");
  static_assert((kLeafBit >> kCountShift) == 16, "packet counts 1..16 must fit between the leaf bit and the unit");
  static_assert(sizeof(LeafUnit) == sizeof(Triangle4), "a single packet is laid out as a Triangle4");
  if (s.maxLeafSize < 1 || s.maxLeafSize > 64) throw SettingsError("HBVH max leaf size must be in [1, 64]");
  if (s.leafTestWidth < 1 || s.leafTestWidth > 64) throw SettingsError("HBVH leaf test width must be in [1, 64]");
  if (!(s.sphereTestCost >= 0.0f)) throw SettingsError("HBVH sphere test cost must be at least 0");
  if (s.quantizeBelow < 0 || s.quantizeMinTriangles < 0)
    throw SettingsError("HBVH quantization thresholds must be at least 0");
  if (triangles.size() >= (1u << 25)) throw SettingsError("HBVH: at most 2^25 - 1 triangles");
  Timer timer;
  PrimRefs refs;
  // Binary build nodes (stable addresses; freed together: 337k nodes for the dragon were 337k
  // allocations and a recursive free).
  Arena<BuildNode> arena;

  // References for every triangle with finite, indexable vertices.
  // In parallel into every slot; a triangle that cannot be bounded leaves its slot invalid
  // (PrimRef::kInvalid), and the slots are compacted in order only when there is one.
  // They lie in the memory that becomes the tree's block store (m_blocks) once the binary tree
  // is built and their triangle ids are copied out: on these VMs memory a process touches for
  // the first time costs about 2.5 ms a MB to fault in (docs/benchmarks.md), and the knot's 320
  // MB of references were a fifth of its build (3.84-4.01 s, now 3.05-3.30). The store is
  // reserved for 64 bytes a triangle (the dragon's tree takes 51, the knot's 46); a tree that
  // needs more gets fresh memory.
  decltype(m_blocks) storage;
  const size_t refLines = (triangles.size() * sizeof(PrimRef) + sizeof(BlockLine) - 1) / sizeof(BlockLine);
  try {
    storage.reserve(std::max(refLines, triangles.size()));  // a line (64 bytes) a triangle
  } catch (const std::bad_alloc&) {
    storage.reserve(refLines);  // address space refused (strict overcommit): the references alone
  }
  storage.resize(refLines);
  static_assert(sizeof(BlockLine) % sizeof(PrimRef) == 0 && alignof(BlockLine) >= alignof(PrimRef),
                "references tile the block store's lines");
  refs = {reinterpret_cast<PrimRef*>(storage.data()), triangles.size()};  // each made in place below
  std::atomic<bool> anyInvalid{false};
  tbb::parallel_for(tbb::blocked_range<uint32_t>(0, uint32_t(triangles.size()), 16384),
                    [&](const tbb::blocked_range<uint32_t>& r) {
                      for (uint32_t i = r.begin(); i < r.end(); ++i) {
                        Bounds3 box;
                        const bool ok = triangleBounds(positions, triangles[i], box);
                        if (!ok) anyInvalid = true;
                        new (&refs[i]) PrimRef(box, ok ? i | PrimRef::kIdTag : PrimRef::kInvalid);
                      }
                    });
  if (anyInvalid)
    refs.count = size_t(std::remove_if(refs.begin(), refs.end(),
                                       [](const PrimRef& r) { return r.tagged() == PrimRef::kInvalid; }) -
                        refs.begin());
  if (progress) progress->start("hbvh", refs.size());
  m_nodes.clear();
  m_spheres.clear();
  m_blocks.clear();
  m_stats = HbvhStats();
  m_bounds = Bounds3();
  m_stats.triangles = refs.size();
  if (refs.empty()) {
    if (progress) progress->finish();
    m_stats.buildSeconds = timer.seconds();
    return;
  }
  BuildNode* root = buildBinaryTree(refs, arena, s, progress);

  // Every stored child box is padded outwards by kBoxPaddingRelative of the largest coordinate
  // magnitude, so that rays whose origin components lie within paddedOriginBound take Embree's
  // one-FMA box test conservatively (paddedOriginBound, above: 4.8 times that coordinate).
  m_bounds = root->box;
  const float sceneMax = maxComponent(glm::max(glm::abs(root->box.lo), glm::abs(root->box.hi)));
  const float pad = sceneMax <= 0x1p26f ? float(double(sceneMax) * kBoxPaddingRelative + 0x1p-68) : 0.0f;

  // Collapse to kWidth children per node and flatten depth first.
  std::vector<uint32_t> ids(refs.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, refs.size(), 16384), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i < r.end(); ++i) ids[i] = refs[i].id();
  });
  refs = {};  // from here on the memory is the block store's
  Flattener flat{*this, ids, positions, triangles, pad};
  uint64_t binaryNodes = 0, leaves = 0;
  m_stats.sahCost = flat.sah(*root, std::max(root->area, 1e-30f), binaryNodes, leaves);
  // A single leaf still needs a node to hold its box: measure() makes it the root's only kid.
  std::atomic<uint64_t> qnodes{0};
  m_stats.maxDepth = flat.measure(*root, false, qnodes);  // the root is a full Node
  if (root->wideNodes > kQuantBit) throw SettingsError("HBVH: too many nodes for 30-bit references");
  if (root->wideUnits > kSlotMask) throw SettingsError("HBVH: leaf data over 4 GiB (leaf references hold 2^27 units)");
  m_nodes.resize(root->wideNodes);
  m_spheres.resize(root->wideSpheres);
  const size_t lines = root->wideUnits / Flattener::kLineUnits;
  if (lines <= storage.capacity()) m_blocks = std::move(storage);
  else storage = decltype(m_blocks)();
  m_blocks.resize(lines);
  flat.fill(*root, 0, 0, 0, false);
  m_stats.quantizedNodes = qnodes;
  m_stats.nodes = m_nodes.size() / 2 + qnodes;  // two slots a Node
  m_stats.leaves = leaves;
  m_stats.binaryNodes = binaryNodes;
  m_stats.sphereNodes = m_spheres.size();
  m_stats.avgLeafSize = m_stats.leaves ? double(ids.size()) / double(m_stats.leaves) : 0.0;
  m_stats.bytes =
      m_nodes.size() * sizeof(NodeSlot) + m_spheres.size() * sizeof(Vec4) + m_blocks.size() * sizeof(BlockLine);
  float planes;
  const uint32_t planeBits = flat.planeBound.load();
  std::memcpy(&planes, &planeBits, sizeof planes);
  m_stats.boxPadding = pad;
  m_stats.paddedOriginBound = paddedOriginBound(pad, planes);
  // Free the build trees before timing stops.
  arena.clear();
  m_stats.buildSeconds = timer.seconds();
  if (progress) progress->finish();
}

nlohmann::json Hbvh::statsJson() const {
  nlohmann::json j = m_stats.toJson();
  j["kind"] = kind();
  j["simd"] = simdName(m_simd);
  return j;
}

}  // namespace voxcone

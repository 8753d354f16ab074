/// \file hbvh_binned_sah.cpp
/// The HBVH's binary tree: top-down binned SAH (Wald 2007, "On fast Construction of SAH-based
/// Bounding Volume Hierarchies"), subtrees built in parallel with TBB. The tree is the same at
/// any thread count: partitions are deterministic and subtrees are joined by position, not by
/// completion order. The split heuristic lives apart from the node layout, as in Embree
/// (kernels/builders/ against kernels/bvh/).

#include "hbvh_build_types.h"

#include "voxcone/core/error.h"
#include "voxcone/core/progress.h"

#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/parallel_reduce.h>
#include <tbb/blocked_range.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <limits>
#include <memory>
#include <utility>

namespace voxcone {
namespace hbvh_build {

namespace {

constexpr int kMaxDepth = 60;  // binary depth; the 8-wide tree is shallower, stacks hold 7 per level
constexpr int kMaxBins = 256;
/// Ranges at least this large are binned in parallel chunks (merged exactly: min, max, counts).
constexpr uint32_t kParallelBinning = 65536;
/// Ranges at least this large are binned into two sets of bins, even and odd references, then
/// merged: neighbours often share a bin, and each add to a bin waits for the previous one's
/// store. The threshold hardly matters above the merge's cost (dragon, rdtsc, split search of
/// the whole build: 177 / 177 / 179 Mcycles at 16 / 64 / 256, 186 with one set throughout).
constexpr uint32_t kTwoBinSets = 64;

/// Per axis and bin: the bounds of the primitives whose centroid falls in it, and their count.
struct Bins {
  Box4 box[3][kMaxBins];
  uint32_t count[3][kMaxBins];
  explicit Bins(int bins) { clear(bins); }
  void merge(const Bins& o, int bins) {
    for (int a = 0; a < 3; ++a)
      for (int i = 0; i < bins; ++i) {
        box[a][i].extend(o.box[a][i]);
        count[a][i] += o.count[a][i];
      }
  }
  /// This thread's bins in `slot`, cleared for `bins` bins (made on first use). For code that runs
  /// no TBB work while it holds them, so nothing else on the thread can take them meanwhile.
  static Bins& cleared(std::unique_ptr<Bins>& slot, int bins) {
    if (!slot) slot = std::make_unique<Bins>(bins);
    else slot->clear(bins);
    return *slot;
  }
  void clear(int bins) {
    for (int a = 0; a < 3; ++a)
      for (int i = 0; i < bins; ++i) {
        box[a][i] = Box4();
        count[a][i] = 0;
      }
  }
};

/// The bin of a doubled centroid per axis: floor((c2 - c2lo) * scale) clamped to [0, bins - 1],
/// in SSE (the same arithmetic for binning and for the partition, so both agree).
struct BinMap {
  __m128 base, scale, top;
  int count;  ///< bins per axis
  BinMap(const Box4& centroids2, int bins) : count(bins) {
    alignas(16) float lo[4], hi[4], sc[4];
    _mm_store_ps(lo, centroids2.lo);
    _mm_store_ps(hi, centroids2.hi);
    for (int a = 0; a < 4; ++a) {
      const float extent = a < 3 ? hi[a] - lo[a] : 0.0f;
      sc[a] = extent > 0.0f ? float(bins) / extent : 0.0f;
    }
    base = centroids2.lo;
    scale = _mm_load_ps(sc);
    top = _mm_set1_ps(float(bins - 1));
  }
  __m128i bins(const PrimRef& r) const {
    const __m128 f = _mm_mul_ps(_mm_sub_ps(_mm_add_ps(r.lo, r.hi), base), scale);
    return _mm_cvttps_epi32(_mm_min_ps(_mm_max_ps(f, _mm_setzero_ps()), top));
  }
  bool splittable(int axis) const {
    alignas(16) float sc[4];
    _mm_store_ps(sc, scale);
    return sc[axis] > 0.0f;
  }
};

class Builder {
public:
  Builder(const HbvhBuildSettings& s, Progress* p, const PrimRefs& r, Arena<BuildNode>& a)
      : refs(r), arena(a), m_s(s), m_progress(p) {}

  const PrimRefs& refs;
  /// Build nodes (stable addresses; freed together: 337k nodes for the dragon were 337k
  /// allocations and a recursive free).
  Arena<BuildNode>& arena;

  /// The root's range: its bounds from every reference.
  Range rootRange() const {
    auto body = [&](const tbb::blocked_range<uint32_t>& r, Range acc) {
      for (uint32_t i = r.begin(); i < r.end(); ++i) {
        acc.box.extend(refs[i].lo, refs[i].hi);
        const __m128 c2 = _mm_add_ps(refs[i].lo, refs[i].hi);
        acc.centroids2.extend(c2, c2);
      }
      return acc;
    };
    Range all = tbb::parallel_reduce(tbb::blocked_range<uint32_t>(0, uint32_t(refs.size()), 16384), Range(), body,
                                     [](Range a, const Range& b) {
                                       a.box.extend(b.box);
                                       a.centroids2.extend(b.centroids2);
                                       return a;
                                     });
    all.begin = 0;
    all.end = uint32_t(refs.size());
    return all;
  }

  /// Build the subtree of `range` into `node`.
  void build(const Range& range, int depth, BuildNode* node) {
    const uint32_t begin = range.begin, end = range.end, count = end - begin;
    node->box = range.box.bounds();
    node->area = node->box.area();
    node->first = begin;
    node->count = count;

    const float leafCost = m_s.intersectionCost * static_cast<float>(packets(count));
    int bestAxis = -1, bestSplit = -1;
    float bestCost = kInf;
    const BinMap map(range.centroids2, binsFor(count));
    // Past kMaxDepth only oversized leaves are split further, at the median: the depth stays
    // below kMaxDepth + log2(triangles).
    const bool mustSplit = count > static_cast<uint32_t>(m_s.maxLeafSize);
    // Every split costs at least the traversal step: where that alone is the leaf's cost (one
    // packet at the default costs) the leaf wins without binning (the same tree, 8% faster).
    const bool splitCanWin = mustSplit || m_s.traversalCost < leafCost;
    if (count > 1 && depth < kMaxDepth && splitCanWin) findSplit(range, map, bestAxis, bestSplit, bestCost);

    if (count == 1 || (!mustSplit && (depth >= kMaxDepth || leafCost <= bestCost))) {
      if (m_progress) m_progress->advance(count);
      node->cost = leafCost;
      return;
    }
    Range left, right;
    if (bestAxis >= 0) partition(range, map, bestAxis, bestSplit, left, right);
    if (bestAxis < 0 || left.end == begin || left.end == end) medianSplit(range, left, right);

    BuildNode* kids = arena.make(2);
    node->kids = kids;
    if (count >= static_cast<uint32_t>(m_s.parallelThreshold)) {
      // A 10M-triangle build takes seconds: stop it when asked (every subtree of this size is
      // milliseconds).
      if (m_progress && m_progress->cancelled()) throw CancelledError();
      tbb::parallel_invoke([&] { build(left, depth + 1, &kids[0]); }, [&] { build(right, depth + 1, &kids[1]); });
    } else {
      build(left, depth + 1, &kids[0]);
      build(right, depth + 1, &kids[1]);
    }
    const float area = node->area;
    node->cost = m_s.traversalCost + (area > 0.0f ? (kids[0].area * kids[0].cost + kids[1].area * kids[1].cost) / area
                                                  : kids[0].cost + kids[1].cost);
  }

private:
  /// Bins for a range of n triangles: 8 + n / 16, up to the settings' count (Embree's
  /// BinMapping takes 4 + n / 20, which made the dragon's SAH 43.29 against 43.10): most ranges
  /// are small, and a sweep over 16 bins of a dozen triangles was most of their split search.
  int binsFor(uint32_t n) const { return int(std::min<uint32_t>(uint32_t(m_s.binCount), 8u + n / 16u)); }

  /// Leaf tests of n triangles (HbvhBuildSettings::leafTestWidth at a time).
  uint32_t packets(uint32_t n) const { return (n + uint32_t(m_s.leafTestWidth) - 1u) / uint32_t(m_s.leafTestWidth); }

  /// Bin prims[begin, end) on all three axes into `bins` (SSE: one bin index per axis at once).
  static void binRange(const PrimRef* prims, uint32_t begin, uint32_t end, const BinMap& map, Bins& bins) {
    const auto add = [&](Bins& to, const PrimRef& r) {
      alignas(16) int32_t idx[4];
      _mm_store_si128(reinterpret_cast<__m128i*>(idx), map.bins(r));
      for (int a = 0; a < 3; ++a) {
        to.box[a][idx[a]].extend(r.lo, r.hi);
        ++to.count[a][idx[a]];
      }
    };
    uint32_t i = begin;
    if (end - begin >= kTwoBinSets) {
      thread_local std::unique_ptr<Bins> oddSlot;
      Bins& odd = Bins::cleared(oddSlot, map.count);
      for (; i + 1 < end; i += 2) {
        add(bins, prims[i]);
        add(odd, prims[i + 1]);
      }
      bins.merge(odd, map.count);
    }
    for (; i < end; ++i) add(bins, prims[i]);
  }

  /// Binned SAH over the three axes: the split plane of least cost. Large ranges are binned in
  /// parallel chunks and merged (exact: the same bins at any thread count).
  void findSplit(const Range& range, const BinMap& map, int& bestAxis, int& bestSplit, float& bestCost) {
    const int nb = map.count;
    const PrimRef* prims = refs.data();
    const float invArea = 1.0f / std::max(range.box.area(), 1e-30f);
    // Bins for a chunk of the range; chunks are joined by min, max and sums: exact.
    struct Body {
      const PrimRef* prims;
      const BinMap& map;
      int nb;
      std::unique_ptr<Bins> bins;
      Body(const PrimRef* p, const BinMap& m, int n) : prims(p), map(m), nb(n), bins(std::make_unique<Bins>(n)) {}
      Body(Body& o, tbb::split) : prims(o.prims), map(o.map), nb(o.nb), bins(std::make_unique<Bins>(o.nb)) {}
      void operator()(const tbb::blocked_range<uint32_t>& r) { binRange(prims, r.begin(), r.end(), map, *bins); }
      void join(const Body& o) { bins->merge(*o.bins, nb); }
    };
    // Small ranges (nearly every node) bin into this thread's scratch bins (binRange runs no
    // TBB work).
    thread_local std::unique_ptr<Bins> scratch;
    std::optional<Body> body;
    const Bins* bins;
    if (range.end - range.begin >= kParallelBinning) {
      body.emplace(prims, map, nb);
      tbb::parallel_reduce(tbb::blocked_range<uint32_t>(range.begin, range.end, 16384), *body);
      bins = body->bins.get();
    } else {
      Bins& own = Bins::cleared(scratch, nb);
      binRange(prims, range.begin, range.end, map, own);
      bins = &own;
    }
    for (int axis = 0; axis < 3; ++axis) {
      if (!map.splittable(axis)) continue;
      // Sweep from the right to get the right-hand areas, then from the left.
      std::array<float, kMaxBins> rightArea;
      std::array<uint32_t, kMaxBins> rightCount;
      Box4 acc;
      uint32_t n = 0;
      for (int i = nb - 1; i > 0; --i) {
        acc.extend(bins->box[axis][i]);
        n += bins->count[axis][i];
        rightArea[i] = acc.area();
        rightCount[i] = n;
      }
      acc = Box4();
      n = 0;
      for (int i = 1; i < nb; ++i) {
        acc.extend(bins->box[axis][i - 1]);
        n += bins->count[axis][i - 1];
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

  /// Split `range` in place at bin `split` of `axis` (left: bins below it), the children's
  /// bounds gathered on the way (no separate pass over each child). Ranges of up to
  /// kScratchPartition references go through a scratch array and back, without a branch on the
  /// side; larger ones by swaps (Hoare), whose branches the long runs of one side at the top of
  /// the tree keep predicted. Cycles an element (rdtsc, dragon, AMD Zen 5): swaps 21 at ranges
  /// of 8-15 down to 7 above 2^18, the scratch array 7-9 throughout.
  void partition(const Range& range, const BinMap& map, int axis, int split, Range& left, Range& right) {
    if (range.end - range.begin > kScratchPartition) {
      partitionInPlace(range, map, axis, split, left, right);
      return;
    }
    if (axis == 0) partitionScratch<0>(range, map, split, left, right);
    else if (axis == 1) partitionScratch<1>(range, map, split, left, right);
    else partitionScratch<2>(range, map, split, left, right);
  }
  static constexpr uint32_t kScratchPartition = 16384;  ///< references: 512 KiB of scratch a thread

  void partitionInPlace(const Range& range, const BinMap& map, int axis, int split, Range& left, Range& right) {
    const __m128i splitV = _mm_set1_epi32(split);
    auto isLeft = [&](const PrimRef& r) {
      return (_mm_movemask_ps(_mm_castsi128_ps(_mm_cmplt_epi32(map.bins(r), splitV))) >> axis) & 1;
    };
    // The sides' bounds in locals: in `left` and `right` (references GCC cannot prove apart
    // from refs) every element was a load, a min and a store, one store-forwarding chain.
    Box4 leftBox, leftC2, rightBox, rightC2;
    auto add = [](Box4& box, Box4& c2s, const PrimRef& r) {
      box.extend(r.lo, r.hi);
      const __m128 c2 = _mm_add_ps(r.lo, r.hi);
      c2s.extend(c2, c2);
    };
    uint32_t i = range.begin, j = range.end;
    while (true) {
      while (i < j && isLeft(refs[i])) add(leftBox, leftC2, refs[i++]);
      while (i < j && !isLeft(refs[j - 1])) add(rightBox, rightC2, refs[--j]);
      if (i >= j) break;
      std::swap(refs[i], refs[j - 1]);
      add(leftBox, leftC2, refs[i++]);
      add(rightBox, rightC2, refs[--j]);
    }
    setSides(range, i, leftBox, leftC2, rightBox, rightC2, left, right);
  }

  /// Each reference is written at the next left slot and at the next right slot (from the end
  /// down) of this thread's scratch array, and only its side's cursor moves; the sides' bounds
  /// take the element or an empty box by mask. Then the range is copied back.
  template <int Axis>
  void partitionScratch(const Range& range, const BinMap& map, int split, Range& left, Range& right) {
    thread_local std::vector<PrimRef> scratch;  // kept for the thread's next builds
    const uint32_t n = range.end - range.begin;
    if (scratch.size() < n) scratch.resize(kScratchPartition);
    const PrimRef* src = refs.data() + range.begin;
    PrimRef* dst = scratch.data();
    const __m128i splitV = _mm_set1_epi32(split);
    const __m128 inf = _mm_set1_ps(kInf), negInf = _mm_set1_ps(-kInf);
    Box4 leftBox, leftC2, rightBox, rightC2;
    uint32_t l = 0, r = n - 1;  // r wraps below 0 only after the last reference
    for (uint32_t i = 0; i < n; ++i) {
      const PrimRef p = src[i];
      const __m128i below = _mm_cmplt_epi32(map.bins(p), splitV);
      const __m128 mask = _mm_castsi128_ps(_mm_shuffle_epi32(below, _MM_SHUFFLE(Axis, Axis, Axis, Axis)));
      const uint32_t isLeft = uint32_t(_mm_movemask_ps(mask)) & 1u;
      dst[l] = p;
      dst[r] = p;
      l += isLeft;
      r -= isLeft ^ 1u;
      const __m128 c2 = _mm_add_ps(p.lo, p.hi);
      leftBox.extend(_mm_blendv_ps(inf, p.lo, mask), _mm_blendv_ps(negInf, p.hi, mask));
      leftC2.extend(_mm_blendv_ps(inf, c2, mask), _mm_blendv_ps(negInf, c2, mask));
      rightBox.extend(_mm_blendv_ps(p.lo, inf, mask), _mm_blendv_ps(p.hi, negInf, mask));
      rightC2.extend(_mm_blendv_ps(c2, inf, mask), _mm_blendv_ps(c2, negInf, mask));
    }
    std::memcpy(static_cast<void*>(refs.data() + range.begin), dst, n * sizeof(PrimRef));
    setSides(range, range.begin + l, leftBox, leftC2, rightBox, rightC2, left, right);
  }

  static void setSides(const Range& range, uint32_t mid, const Box4& leftBox, const Box4& leftC2,
                       const Box4& rightBox, const Box4& rightC2, Range& left, Range& right) {
    left.box = leftBox;
    left.centroids2 = leftC2;
    right.box = rightBox;
    right.centroids2 = rightC2;
    left.begin = range.begin;
    left.end = right.begin = mid;
    right.end = range.end;
  }

  /// Every centroid coincides (or no split helps yet the leaf would be too big): split the
  /// range in its middle, ordered by the largest centroid axis (then id) for a stable result.
  void medianSplit(const Range& range, Range& left, Range& right) {
    const Bounds3 c = range.centroids2.bounds();
    const int axis = maxDimension(c.diagonal());
    const uint32_t mid = range.begin + (range.end - range.begin) / 2;
    auto key = [axis](const PrimRef& r) { return r.box().center()[axis]; };
    PrimRef* prims = refs.data();
    std::nth_element(prims + range.begin, prims + mid, prims + range.end,
                     [&](const PrimRef& a, const PrimRef& b) {
                       return key(a) < key(b) || (key(a) == key(b) && a.id() < b.id());
                     });
    left = Range();
    right = Range();
    for (uint32_t i = range.begin; i < range.end; ++i) {
      Range& to = i < mid ? left : right;
      to.box.extend(prims[i].lo, prims[i].hi);
      const __m128 c2 = _mm_add_ps(prims[i].lo, prims[i].hi);
      to.centroids2.extend(c2, c2);
    }
    left.begin = range.begin;
    left.end = right.begin = mid;
    right.end = range.end;
  }

  const HbvhBuildSettings& m_s;
  Progress* m_progress;
};

}  // namespace

BuildNode* buildBinaryTree(const PrimRefs& refs, Arena<BuildNode>& arena, const HbvhBuildSettings& settings,
                           Progress* progress) {
  Builder builder(settings, progress, refs, arena);
  arena.expect(2 * refs.size());  // a binary tree of n leaves has 2n - 1 nodes
  BuildNode* root = arena.make();
  builder.build(builder.rootRange(), 0, root);
  return root;
}

}  // namespace hbvh_build
}  // namespace voxcone

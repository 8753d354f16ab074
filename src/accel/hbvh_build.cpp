// HBVH construction: top-down binned SAH (Wald 2007, "On fast Construction of SAH-based
// Bounding Volume Hierarchies"), subtrees built in parallel with TBB, then flattened depth
// first. The tree is the same at any thread count: partitions are deterministic and subtrees
// are joined by position, not by completion order.

#include "voxcone/accel/hbvh.h"
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

namespace {

/// The box whose corners are the xyz lanes of lo and hi.
Bounds3 toBounds(__m128 lo, __m128 hi) {
  alignas(16) float l[4], h[4];
  _mm_store_ps(l, lo);
  _mm_store_ps(h, hi);
  Bounds3 b;
  b.lo = Vec3(l[0], l[1], l[2]);
  b.hi = Vec3(h[0], h[1], h[2]);
  return b;
}

/// A triangle's bounds during the build, as two SSE vectors (32 bytes; the id in lo's w lane,
/// by its bits). lo + hi is twice the centroid: binning works on it directly.
/// The w lanes take part in that arithmetic, so the id is stored with kIdTag set: a normal float
/// in [2, 32) for any id below 2^25. As the bare id it was a denormal, and every add of a
/// reference's lanes took a microcode assist wherever denormals are not flushed (the whole build
/// 590 -> 302 ms on the dragon, AMD Zen 5; Embree sets FTZ/DAZ for its builds and asks its
/// callers to set them, a library cannot count on a caller's MXCSR).
struct alignas(16) PrimRef {
  static constexpr uint32_t kIdTag = 0x40000000u;
  /// A triangle that cannot be bounded (a NaN: removed before the build).
  static constexpr uint32_t kInvalid = ~0u;
  PrimRef() {}  // filled in parallel right after the array is sized: no zeroing first
  PrimRef(const Bounds3& box, uint32_t tagged)
      : lo(_mm_castsi128_ps(_mm_insert_epi32(_mm_castps_si128(_mm_setr_ps(box.lo.x, box.lo.y, box.lo.z, 0.0f)),
                                             int32_t(tagged), 3))),
        hi(_mm_setr_ps(box.hi.x, box.hi.y, box.hi.z, 0.0f)) {}
  __m128 lo, hi;
  uint32_t tagged() const { return uint32_t(_mm_cvtsi128_si32(_mm_castps_si128(_mm_shuffle_ps(lo, lo, 0xff)))); }
  uint32_t id() const { return tagged() & ~kIdTag; }
  Bounds3 box() const { return toBounds(lo, hi); }
};

/// An axis-aligned box as two SSE vectors (w lanes unused), empty when lo > hi.
struct Box4 {
  __m128 lo = _mm_set1_ps(kInf), hi = _mm_set1_ps(-kInf);
  void extend(__m128 l, __m128 h) {
    lo = _mm_min_ps(lo, l);
    hi = _mm_max_ps(hi, h);
  }
  void extend(const Box4& b) { extend(b.lo, b.hi); }
  Bounds3 bounds() const { return toBounds(lo, hi); }
  /// Surface area (0 when empty: the extents clamp to 0), 2 (dx dy + dy dz + dz dx) summed in
  /// that order, without leaving the registers (the SAH sweep calls it twice a bin).
  float area() const {
    const __m128 d = _mm_max_ps(_mm_sub_ps(hi, lo), _mm_setzero_ps());
    const __m128 p = _mm_mul_ps(d, _mm_shuffle_ps(d, d, _MM_SHUFFLE(3, 0, 2, 1)));  // dx dy, dy dz, dz dx
    const float sum = (_mm_cvtss_f32(p) + _mm_cvtss_f32(_mm_shuffle_ps(p, p, 1))) + _mm_cvtss_f32(_mm_shuffle_ps(p, p, 2));
    return 2.0f * sum;
  }
};

/// A node's range with its bounds and the bounds of its doubled centroids (lo + hi).
struct Range {
  uint32_t begin = 0, end = 0;
  Box4 box, centroids2;
};

struct BuildNode {
  Bounds3 box;
  BuildNode* kids = nullptr;  // the two children, side by side in the builder's arena
  float area = 0.0f;  ///< box.area(), which the collapse compares over and over
  /// No vertex of the subtree lies farther than this from box.center(): exact at leaves, from
  /// the children's bounds above (Hbvh::Flattener::reachOf); kReachUnknown until a bounding
  /// sphere needs it (most boxes are rejected without: computing every node's read every vertex).
  mutable float reach = kReachUnknown;
  /// SAH cost of the subtree once a ray is inside its box (leaf tests and node visits, in
  /// HbvhBuildSettings' cost units): what a tighter bound around it can save.
  float cost = 0.0f;
  uint32_t first = 0, count = 0;  // range in the ref array (for inner nodes: of the subtree)
  /// Of the 8-wide node collapsed from this one, where it is one (Hbvh::Flattener::measure):
  /// its subtree's node slots (Hbvh::NodeSlot), spheres and block units (Hbvh::kUnitBytes: its
  /// QNodes and leaves, an even number).
  uint32_t wideNodes = 0, wideSpheres = 0, wideUnits = 0;
  static constexpr float kReachUnknown = -1.0f;
  bool leaf() const { return !kids; }
};
static_assert(sizeof(BuildNode) == 64, "a build node is one cache line");

/// Objects made per thread in 2 MiB blocks of huge pages and freed together. A build makes a
/// node object for every binary node (2.7M, 170 MB for the 10M knot): one allocation each was a
/// 4 KiB page fault every 64 of them, and on a virtual machine a fault costs 10 us (first touch
/// of 4 KiB pages 2.7 ms a MiB, of fresh huge pages 1.7, of reused ones 0.1: AMD Zen 5 VM).
/// Embree's builders allocate in blocks too (its FastAllocator). A build that needs fewer
/// objects than a block holds (expect()) gets smaller blocks of ordinary memory: a 12-triangle
/// scene should not fault in a 2 MiB page.
template <class T>
class Arena {
  static_assert(std::is_trivially_destructible_v<T>, "an arena frees its blocks without destroying objects");
  static_assert(alignof(T) <= 16, "blocks are aligned to 16 bytes at least (operator new's)");

public:
  Arena() = default;
  Arena(const Arena&) = delete;
  Arena& operator=(const Arena&) = delete;
  ~Arena() { clear(); }

  /// Blocks sized for at most `objects` in all (set before the first make()).
  void expect(size_t objects) { m_perBlock = std::max<size_t>(std::min(objects, kPerHugeBlock), 2); }

  /// n default-constructed objects side by side (n <= 2).
  T* make(size_t n = 1) {
    Local& l = m_local.local();
    if (l.blocks.empty() || l.used + n > m_perBlock) {
      l.blocks.push_back(m_alloc.allocate(m_perBlock * sizeof(T)));
      l.used = 0;
    }
    T* first = reinterpret_cast<T*>(l.blocks.back() + sizeof(T) * l.used);
    for (size_t i = 0; i < n; ++i) new (first + i) T();
    l.used += n;
    return first;
  }
  void clear() {
    for (Local& l : m_local)
      for (unsigned char* b : l.blocks) m_alloc.deallocate(b, m_perBlock * sizeof(T));
    m_local.clear();
  }

private:
  static constexpr size_t kPerHugeBlock = HugePageAllocator<unsigned char>::kHugePage / sizeof(T);
  struct Local {
    std::vector<unsigned char*> blocks;
    size_t used = 0;
  };
  tbb::enumerable_thread_specific<Local> m_local;
  HugePageAllocator<unsigned char> m_alloc;
  size_t m_perBlock = kPerHugeBlock;
};

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

/// The build's references, in memory that Hbvh::build hands on to the tree's block store once
/// the binary tree is built (it says why).
struct PrimRefs {
  PrimRef* first = nullptr;
  size_t count = 0;
  size_t size() const { return count; }
  bool empty() const { return count == 0; }
  PrimRef* data() const { return first; }
  PrimRef* begin() const { return first; }
  PrimRef* end() const { return first + count; }
  PrimRef& operator[](size_t i) const { return first[i]; }
};

class Builder {
public:
  Builder(const HbvhBuildSettings& s, Progress* p) : m_s(s), m_progress(p) {}

  PrimRefs refs;
  /// Build nodes (stable addresses; freed together: 337k nodes for the dragon were 337k
  /// allocations and a recursive free).
  Arena<BuildNode> arena;

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
  Builder builder(s, progress);

  // References for every triangle with finite, indexable vertices.
  // In parallel into every slot; a triangle that cannot be bounded leaves its slot invalid
  // (PrimRef::kInvalid), and the slots are compacted in order only when there is one.
  // They lie in the memory that becomes the tree's block store (m_blocks) once the binary tree
  // is built and their triangle ids are copied out: on these VMs memory a process touches for
  // the first time costs about 2.5 ms a MB to fault in (README, Benchmarks), and the knot's 320
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
  auto& refs = builder.refs;
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
  if (progress) progress->start("hbvh", builder.refs.size());
  m_nodes.clear();
  m_spheres.clear();
  m_blocks.clear();
  m_stats = HbvhStats();
  m_bounds = Bounds3();
  m_stats.triangles = builder.refs.size();
  if (builder.refs.empty()) {
    if (progress) progress->finish();
    m_stats.buildSeconds = timer.seconds();
    return;
  }
  builder.arena.expect(2 * refs.size());  // a binary tree of n leaves has 2n - 1 nodes
  BuildNode* root = builder.arena.make();
  builder.build(builder.rootRange(), 0, root);

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
  builder.arena.clear();
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

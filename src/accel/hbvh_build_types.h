#pragma once
/// \file hbvh_build_types.h
/// The HBVH build's internal types, shared by the binned SAH builder (hbvh_binned_sah.cpp) and the
/// collapse into 8-wide nodes (hbvh_build.cpp): triangle references as SSE boxes, the binary
/// build nodes and the arena they live in. Not a public header.

#include "voxcone/accel/hbvh.h"
#include "voxcone/core/huge_pages.h"

#include <tbb/enumerable_thread_specific.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <new>
#include <type_traits>
#include <vector>

#include <smmintrin.h>

namespace voxcone {
class Progress;
namespace hbvh_build {

/// The box whose corners are the xyz lanes of lo and hi.
inline Bounds3 toBounds(__m128 lo, __m128 hi) {
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

/// Builds the binary SAH tree over `refs` (reordered in place) with nodes from `arena`, and
/// returns its root (refs not empty): top-down binned SAH, subtrees in parallel, the same tree at
/// any thread count (hbvh_binned_sah.cpp).
BuildNode* buildBinaryTree(const PrimRefs& refs, Arena<BuildNode>& arena, const HbvhBuildSettings& settings,
                           Progress* progress);

}  // namespace hbvh_build
}  // namespace voxcone

#pragma once
// The HBVH's traversal kernels, one set per instruction set (as Embree's isa namespaces): the
// same source (hbvh_traverse_kernel.h) compiled for SSE 4.2 in hbvh_traverse.cpp, for AVX2 in
// hbvh_traverse_avx2.cpp and for AVX-512 in hbvh_traverse_avx512.cpp; Hbvh::intersect / occluded
// call the one Hbvh::simd() names.

#include "voxcone/accel/hbvh.h"

#include <optional>

namespace voxcone {

/// The arrays a traversal reads; nodes[0] is the root (the tree is not empty).
struct HbvhArrays {
  const Hbvh::NodeSlot* nodes;
  const Vec4* spheres;
  const unsigned char* blocks;  ///< Hbvh::m_blocks: QNodes and leaves
  /// Rays whose origin components are all at most this in magnitude take the padded box test
  /// (hbvh_traverse_kernel.h, PaddedBoxRay); -1: none.
  float paddedOriginBound;
  // The accessors are always inlined: an out-of-line copy compiled in the AVX2 or AVX-512
  // kernels' object (as an unoptimized or sanitizer build would emit) could be the one the
  // linker keeps for the baseline kernels too (Hbvh.AvxKernelsShareNoInlineCodeWithTheBaseline).
  /// The node a node reference refers to: a Node (Hbvh::kQuantBit clear) or a QNode (set).
  [[gnu::always_inline]] const Hbvh::Node& node(uint32_t ref) const {
    return *reinterpret_cast<const Hbvh::Node*>(nodes + ref);
  }
  [[gnu::always_inline]] const Hbvh::QNode& qnode(uint32_t ref) const {
    return *reinterpret_cast<const Hbvh::QNode*>(blocks + size_t(ref & ~Hbvh::kQuantBit) * sizeof(Hbvh::BlockLine));
  }
  /// The first float of the leaf whose first unit is `unit`.
  [[gnu::always_inline]] const float* leaf(uint32_t unit) const {
    return reinterpret_cast<const float*>(blocks + size_t(unit) * Hbvh::kUnitBytes);
  }
};

#ifdef VOXCONE_HBVH_COUNTERS
/// Traversal counts of this thread (a diagnostic build only: -DVOXCONE_HBVH_COUNTERS).
struct HbvhCounters {
  uint64_t nodes = 0, leaves = 0, packets = 0;
};
inline HbvhCounters& hbvhCounters() {
  static thread_local HbvhCounters c;
  return c;
}
#endif

namespace sse42 {
std::optional<Hit> hbvhIntersect(const HbvhArrays& bvh, const Ray& ray);
std::optional<Hit> hbvhIntersectLean(const HbvhArrays& bvh, const Ray& ray);  ///< trees without spheres
bool hbvhOccluded(const HbvhArrays& bvh, const Ray& ray, float tMax);
bool hbvhOccludedLean(const HbvhArrays& bvh, const Ray& ray, float tMax);
}  // namespace sse42

#ifdef VOXCONE_AVX2_KERNELS
namespace avx2 {
std::optional<Hit> hbvhIntersect(const HbvhArrays& bvh, const Ray& ray);
std::optional<Hit> hbvhIntersectLean(const HbvhArrays& bvh, const Ray& ray);  ///< trees without spheres
bool hbvhOccluded(const HbvhArrays& bvh, const Ray& ray, float tMax);
bool hbvhOccludedLean(const HbvhArrays& bvh, const Ray& ray, float tMax);
}  // namespace avx2
#endif

#ifdef VOXCONE_AVX512_KERNELS
namespace avx512 {
std::optional<Hit> hbvhIntersect(const HbvhArrays& bvh, const Ray& ray);
std::optional<Hit> hbvhIntersectLean(const HbvhArrays& bvh, const Ray& ray);  ///< trees without spheres
bool hbvhOccluded(const HbvhArrays& bvh, const Ray& ray, float tMax);
bool hbvhOccludedLean(const HbvhArrays& bvh, const Ray& ray, float tMax);
}  // namespace avx512
#endif

}  // namespace voxcone

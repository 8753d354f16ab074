// HBVH traversal: the SSE 4.2 kernels (hbvh_traverse_kernel.h compiled for the baseline
// instruction set), the choice between them and the AVX2 and AVX-512 ones, and the scalar
// fallback of the packet triangle test.

#define VOXCONE_ISA sse42
#include "hbvh_traverse_kernel.h"

#include "voxcone/core/error.h"

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <string>

namespace voxcone {

bool intersectTriangleLane(const float* base, int stride, int lane, const Ray& ray, float tMin, float tMax,
                           float& tOut, float& b1Out, float& b2Out) {
  const WatertightRay wr(ray.dir);
  const auto vertex = [&](int vtx) {
    const float* rows = base + 3 * vtx * stride + lane;
    return Vec3(rows[0], rows[stride], rows[2 * stride]);
  };
  return intersectTriangleWatertight(ray.origin, wr, vertex(0), vertex(1), vertex(2), tMin, tMax, tOut, b1Out, b2Out);
}

namespace {

bool cpuRuns(Hbvh::Simd simd) {
  switch (simd) {
    case Hbvh::Simd::Sse42: return true;
    case Hbvh::Simd::Avx2:
#ifdef VOXCONE_AVX2_KERNELS
      return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
#else
      return false;
#endif
    case Hbvh::Simd::Avx512:
#ifdef VOXCONE_AVX512_KERNELS
      return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") && __builtin_cpu_supports("avx512f") &&
             __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("avx512bw") &&
             __builtin_cpu_supports("avx512dq");
#else
      return false;
#endif
  }
  return false;
}

}  // namespace

std::vector<Hbvh::Simd> Hbvh::runnableSimds() {
  std::vector<Simd> v;
  for (Simd s : {Simd::Sse42, Simd::Avx2, Simd::Avx512})
    if (cpuRuns(s)) v.push_back(s);
  return v;
}

Hbvh::Simd Hbvh::hostSimd() {
  static const Simd best = [] {
    const Simd widest = runnableSimds().back();
    const char* forced = std::getenv("VOXCONE_SIMD");
    if (forced && std::strcmp(forced, "sse4.2") == 0) return Simd::Sse42;
    if (forced && std::strcmp(forced, "avx2") == 0 && cpuRuns(Simd::Avx2)) return Simd::Avx2;
    return widest;
  }();
  return best;
}

const char* Hbvh::simdName(Simd simd) {
  switch (simd) {
    case Simd::Avx2: return "avx2";
    case Simd::Avx512: return "avx512";
    case Simd::Sse42: break;
  }
  return "sse4.2";
}

void Hbvh::setSimd(Simd simd) {
  if (!cpuRuns(simd))
    throw SettingsError(std::string("HBVH: this CPU (or this build) has no ") + simdName(simd) + " kernels");
  m_simd = simd;
}

namespace {

/// The kernels order distances as integers, which needs tMin >= +0 (hbvh_traverse_kernel.h,
/// enterBoxes; -0 orders below every negative float): a ray from before its origin (signbit set)
/// is traced from it, as Embree requires of tnear.
Ray fromOrigin(Ray ray) {
  ray.tMin = 0.0f;
  return ray;
}

}  // namespace

namespace {

/// One instruction set's kernels (setSimd admits only those the CPU runs), for trees with
/// spheres or (lean) without.
struct Kernels {
  std::optional<Hit> (*intersect)(const HbvhArrays&, const Ray&);
  bool (*occluded)(const HbvhArrays&, const Ray&, float);
};

Kernels kernelsFor(Hbvh::Simd simd, bool spheres) {
// One namespace's pair: the full kernels where the tree keeps spheres, the lean ones where not.
#define VOXCONE_KERNELS_OF(isa)                             \
  (spheres ? Kernels{isa::hbvhIntersect, isa::hbvhOccluded} \
           : Kernels{isa::hbvhIntersectLean, isa::hbvhOccludedLean})
  switch (simd) {
#ifdef VOXCONE_AVX512_KERNELS
    case Hbvh::Simd::Avx512: return VOXCONE_KERNELS_OF(avx512);
#endif
#ifdef VOXCONE_AVX2_KERNELS
    case Hbvh::Simd::Avx2: return VOXCONE_KERNELS_OF(avx2);
#endif
    default: return VOXCONE_KERNELS_OF(sse42);
  }
#undef VOXCONE_KERNELS_OF
}

}  // namespace

std::optional<Hit> Hbvh::intersect(const Ray& ray) const {
  if (m_nodes.empty()) return std::nullopt;
  if (std::signbit(ray.tMin)) return intersect(fromOrigin(ray));
  const HbvhArrays arrays{m_nodes.data(), m_spheres.data(), reinterpret_cast<const unsigned char*>(m_blocks.data()),
                          m_stats.paddedOriginBound};
  return kernelsFor(m_simd, !m_spheres.empty()).intersect(arrays, ray);
}

bool Hbvh::occluded(const Ray& ray, float tMax) const {
  if (m_nodes.empty()) return false;
  if (std::signbit(ray.tMin)) return occluded(fromOrigin(ray), tMax);
  const HbvhArrays arrays{m_nodes.data(), m_spheres.data(), reinterpret_cast<const unsigned char*>(m_blocks.data()),
                          m_stats.paddedOriginBound};
  return kernelsFor(m_simd, !m_spheres.empty()).occluded(arrays, ray, tMax);
}

}  // namespace voxcone

// hbvh_bench: the HBVH against Embree 3 on one mesh (default: the full Stanford dragon), same
// rays, one run. Builds both (each once untimed, then in turns, median of 3), traces four
// deterministic ray sets one ray at a time (median of N repetitions; on one thread the
// accelerators take turns block by block, so that machine noise hits both alike), checks that
// both agree on every ray, and prints a table (and JSON with --json).
//
// Embree is linked here only; voxcone_lib never sees it.

#include "voxcone/accel/hbvh.h"
#include "voxcone/core/error.h"
#include "voxcone/core/math.h"
#include "voxcone/core/parallel.h"
#include "voxcone/core/ray.h"
#include "voxcone/core/rng.h"
#include "voxcone/core/sampling.h"
#include "voxcone/core/timer.h"
#include "voxcone/scene/mesh.h"
#ifdef VOXCONE_HBVH_COUNTERS
#include "../src/accel/hbvh_kernels.h"
#endif

#include <CLI/CLI.hpp>
#include <benchmark/benchmark.h>
#include "voxcone/accel/embree_ray.h"

#include <embree3/rtcore.h>
#include <nlohmann/json.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <sys/types.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <functional>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

using namespace voxcone;

namespace {

/// Command-line options.
struct Options {
  std::string meshPath = VOXCONE_SOURCE_DIR "/data/models/dragon_vrip.ply";
  int threads = 1;          ///< tracing and build threads (0 = all)
  int reps = 5;             ///< timed repetitions per set and accelerator
  int buildReps = 3;        ///< builds per accelerator (median reported)
  int resolution = 1024;    ///< primary rays: resolution x resolution pixels
  uint64_t seed = 20240611; ///< seed of every ray set
  std::string light = "above";  ///< the shadow rays' light: above or below the mesh
  bool allQualities = false;
  bool embreeRobust = false;  ///< also Embree MEDIUM with RTC_SCENE_FLAG_ROBUST
  std::string jsonPath;
  std::string set;   ///< trace only this ray set (for a profiler)
  std::string only;  ///< time only this tracer (for a profiler); the others' columns stay empty
  HbvhBuildSettings hbvh;
};

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n == 0 ? 0.0 : (n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]));
}

constexpr double kMiB = 1024.0 * 1024.0;

// ---------------------------------------------------------------------------------------------
// Embree

/// Bytes Embree allocates on one device (rtcSetDeviceMemoryMonitorFunction): current and peak.
struct EmbreeMemory {
  std::atomic<int64_t> current{0};
  std::atomic<int64_t> peak{0};
  void resetPeak() { peak = current.load(); }
};

bool embreeMemoryMonitor(void* user, ssize_t bytes, bool /*post*/) {
  auto* m = static_cast<EmbreeMemory*>(user);
  const int64_t now = m->current.fetch_add(bytes) + bytes;
  int64_t p = m->peak.load();
  while (now > p && !m->peak.compare_exchange_weak(p, now)) {
  }
  return true;
}

/// Embree reports errors through this callback; throwing across its C API is not allowed, so the
/// first message is kept and checked after each build.
std::string g_embreeError;
void embreeError(void* /*user*/, RTCError code, const char* str) {
  if (g_embreeError.empty()) g_embreeError = "embree error " + std::to_string(int(code)) + ": " + (str ? str : "");
}

/// One Embree scene holding the mesh as a single triangle geometry.
class EmbreeScene {
public:
  EmbreeScene(RTCDevice device, const TriangleMesh& mesh, RTCBuildQuality quality, RTCSceneFlags flags) {
    m_scene = rtcNewScene(device);
    rtcSetSceneBuildQuality(m_scene, quality);
    rtcSetSceneFlags(m_scene, flags);
    RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetGeometryBuildQuality(geom, quality);
    // Embree-owned buffers (padded for its SIMD loads), so that they count in its memory.
    auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                           3 * sizeof(float), mesh.positions.size()));
    auto* ib = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                              3 * sizeof(uint32_t), mesh.triangles.size()));
    for (size_t i = 0; i < mesh.positions.size(); ++i)
      std::memcpy(vb + 3 * i, &mesh.positions[i], 3 * sizeof(float));
    for (size_t i = 0; i < mesh.triangles.size(); ++i)
      std::memcpy(ib + 3 * i, &mesh.triangles[i], 3 * sizeof(uint32_t));
    rtcCommitGeometry(geom);
    rtcAttachGeometry(m_scene, geom);
    rtcReleaseGeometry(geom);
    rtcCommitScene(m_scene);
    if (!g_embreeError.empty()) throw Error(g_embreeError);
  }
  ~EmbreeScene() { rtcReleaseScene(m_scene); }
  EmbreeScene(const EmbreeScene&) = delete;
  EmbreeScene& operator=(const EmbreeScene&) = delete;
  RTCScene scene() const { return m_scene; }

private:
  RTCScene m_scene = nullptr;
};


// ---------------------------------------------------------------------------------------------
// Accelerators behind one interface: trace a block of rays, write one float per ray
// (closest t or +inf for intersect; 1 or 0 for occluded).

using BlockFn = std::function<void(const Ray* rays, float* out, size_t n)>;

struct Tracer {
  std::string name;
  BlockFn intersect;
  BlockFn occluded;
};

Tracer hbvhTracer(const Hbvh& bvh) {
  Tracer t;
  t.name = "HBVH";
  t.intersect = [&bvh](const Ray* rays, float* out, size_t n) {
    for (size_t i = 0; i < n; ++i) {
      const auto hit = bvh.intersect(rays[i]);
      out[i] = hit ? hit->t : kInf;
    }
  };
  t.occluded = [&bvh](const Ray* rays, float* out, size_t n) {
    for (size_t i = 0; i < n; ++i) out[i] = bvh.occluded(rays[i], rays[i].tMax) ? 1.0f : 0.0f;
  };
  return t;
}

Tracer embreeTracer(const std::string& name, RTCScene scene) {
  Tracer t;
  t.name = name;
  t.intersect = [scene](const Ray* rays, float* out, size_t n) {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    for (size_t i = 0; i < n; ++i) {
      RTCRayHit rh;
      toEmbree(rays[i], rays[i].tMax, rh.ray);
      rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
      rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
      rtcIntersect1(scene, &ctx, &rh);
      out[i] = rh.hit.geomID != RTC_INVALID_GEOMETRY_ID ? rh.ray.tfar : kInf;
    }
  };
  t.occluded = [scene](const Ray* rays, float* out, size_t n) {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    for (size_t i = 0; i < n; ++i) {
      RTCRay r;
      toEmbree(rays[i], rays[i].tMax, r);
      rtcOccluded1(scene, &ctx, &r);
      // Embree marks an occluded ray by setting tfar to -inf.
      out[i] = r.tfar < 0.0f ? 1.0f : 0.0f;
    }
  };
  return t;
}

/// Rays a tracer takes at a time (a TBB task; a turn of traceInterleaved).
constexpr size_t kBlock = 4096;

size_t blockCount(const std::vector<Ray>& rays) { return (rays.size() + kBlock - 1) / kBlock; }

/// Trace block b of the rays into out.
void traceBlock(const BlockFn& fn, const std::vector<Ray>& rays, std::vector<float>& out, size_t b) {
  const size_t begin = b * kBlock, end = std::min(rays.size(), begin + kBlock);
  fn(rays.data() + begin, out.data() + begin, end - begin);
}

/// Trace all rays in blocks; one thread runs them in order, more threads take blocks from TBB.
/// Returns wall seconds.
double traceAll(const BlockFn& fn, const std::vector<Ray>& rays, std::vector<float>& out, int threads) {
  out.assign(rays.size(), 0.0f);
  const size_t nBlocks = blockCount(rays);
  Timer timer;
  if (threads == 1) {
    for (size_t b = 0; b < nBlocks; ++b) traceBlock(fn, rays, out, b);
  } else {
    tbb::parallel_for(tbb::blocked_range<size_t>(0, nBlocks, 1), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t b = r.begin(); b != r.end(); ++b) traceBlock(fn, rays, out, b);
    });
  }
  const double s = timer.seconds();
  benchmark::DoNotOptimize(out.data());
  benchmark::ClobberMemory();
  return s;
}

/// One thread, every tracer on the same rays: they take turns block by block (which one goes
/// first rotates), each block timed on its own, so that a shared machine's speed, which moves by
/// tens of percent over seconds, is the same for all of them. Whole-set passes one after the
/// other gave ratios that moved by 0.1 between runs of the same binaries. Seconds per tracer.
std::vector<double> traceInterleaved(const std::vector<const BlockFn*>& fns, const std::vector<Ray>& rays,
                                     std::vector<float>& out) {
  out.assign(rays.size(), 0.0f);
  std::vector<double> seconds(fns.size(), 0.0);
  for (size_t b = 0; b < blockCount(rays); ++b)
    for (size_t j = 0; j < fns.size(); ++j) {
      const size_t k = (b + j) % fns.size();
      Timer timer;
      traceBlock(*fns[k], rays, out, b);
      seconds[k] += timer.seconds();
    }
  benchmark::DoNotOptimize(out.data());
  benchmark::ClobberMemory();
  return seconds;
}

// ---------------------------------------------------------------------------------------------
// Ray sets

struct RaySet {
  std::string name;
  bool occlusion = false;
  std::vector<Ray> rays;
};

/// Surface points hit by the primary rays, for the secondary and shadow sets.
struct SurfacePoint {
  Vec3 pos, posError, geomNormal, incoming;
};

/// (a) Primary rays: a pinhole camera on +z looking at the bbox centre, framing the mesh.
RaySet primaryRays(const Bounds3& box, const std::vector<Vec3>& positions, int res) {
  RaySet set{"primary", false, {}};
  const Vec3 c = box.center(), ext = box.diagonal();
  const float radius = 0.5f * glm::length(ext);
  const float dist = 3.0f * radius;
  const Vec3 eye = c + Vec3(0.0f, 0.0f, dist);
  // The smallest field of view that holds every vertex, plus 2%, so the mesh fills the frame.
  float tanHalf = 0.0f;
  for (const Vec3& p : positions) {
    const float depth = eye.z - p.z;
    tanHalf = std::max(tanHalf, std::max(std::fabs(p.x - eye.x), std::fabs(p.y - eye.y)) / depth);
  }
  tanHalf *= 1.02f;
  set.rays.reserve(size_t(res) * res);
  for (int y = 0; y < res; ++y)
    for (int x = 0; x < res; ++x) {
      const float u = (2.0f * (x + 0.5f) / res - 1.0f) * tanHalf;
      const float v = (1.0f - 2.0f * (y + 0.5f) / res) * tanHalf;
      Ray r;
      r.origin = eye;
      r.dir = glm::normalize(Vec3(u, v, -1.0f));
      set.rays.push_back(r);
    }
  return set;
}

/// (b) Incoherent rays: random points on the bounding sphere to random points in the box.
RaySet incoherentRays(const Bounds3& box, size_t count, uint64_t seed) {
  RaySet set{"incoherent", false, {}};
  Rng rng(seed, 2);
  const Vec3 c = box.center(), ext = box.diagonal();
  const float radius = 0.5f * glm::length(ext);
  set.rays.reserve(count);
  for (size_t i = 0; i < count; ++i) {
    const Vec3 from = c + radius * sampleUniformSphere(rng.uniform2());
    const Vec3 to = box.lo + ext * Vec3(rng.uniform(), rng.uniform(), rng.uniform());
    Ray r;
    r.origin = from;
    r.dir = glm::normalize(to - from);
    set.rays.push_back(r);
  }
  return set;
}

/// Closest hits of the primary rays (by the HBVH), as surface points with geometric normals.
std::vector<SurfacePoint> primaryHits(const Hbvh& bvh, const TriangleMesh& mesh, const RaySet& primary) {
  std::vector<SurfacePoint> pts;
  for (const Ray& r : primary.rays) {
    const auto hit = bvh.intersect(r);
    if (!hit) continue;
    const UVec3& tri = mesh.triangles[hit->triangle];
    const Vec3 p0 = mesh.positions[tri.x], p1 = mesh.positions[tri.y], p2 = mesh.positions[tri.z];
    // Barycentric interpolation is more accurate than origin + t dir far from the camera.
    Vec3 pError;
    const Vec3 p = barycentricPoint(p0, p1, p2, 1.0f - hit->b1 - hit->b2, hit->b1, hit->b2, pError);
    const Vec3 ng = glm::normalize(glm::cross(p1 - p0, p2 - p0));
    if (!isFinite(ng)) continue;
    pts.push_back({p, pError, ng, r.dir});
  }
  return pts;
}

/// (c) Secondary rays: cosine-weighted about the normal facing the incoming ray.
RaySet secondaryRays(const std::vector<SurfacePoint>& pts, uint64_t seed) {
  RaySet set{"secondary", false, {}};
  Rng rng(seed, 3);
  set.rays.reserve(pts.size());
  for (const SurfacePoint& sp : pts) {
    const Vec3 n = glm::dot(sp.geomNormal, sp.incoming) < 0.0f ? sp.geomNormal : -sp.geomNormal;
    const Vec3 d = Frame(n).toWorld(sampleCosineHemisphere(rng.uniform2()));
    set.rays.push_back(spawnRay(sp.pos, sp.posError, sp.geomNormal, d));
  }
  return set;
}

/// (d) Shadow rays: from the primary hits to random points on a small square light above the
/// mesh (a quarter of the box's x/z extent, half the box height above its top), tMax to it; with
/// `below`, as far below its bottom. The two show how an any-hit traversal's child order
/// depends on the rays' direction: Embree goes on with a node's last child (highest index),
/// the HBVH with the farthest entered child below a full node.
RaySet occlusionRays(const std::vector<SurfacePoint>& pts, const Bounds3& box, uint64_t seed, bool below) {
  RaySet set{"occlusion", true, {}};
  Rng rng(seed, 4);
  const Vec3 c = box.center(), ext = box.diagonal();
  const float lightY = below ? box.lo.y - 0.5f * ext.y : box.hi.y + 0.5f * ext.y;
  set.rays.reserve(pts.size());
  for (const SurfacePoint& sp : pts) {
    const Vec2 u = rng.uniform2();
    const Vec3 target(c.x + (u.x - 0.5f) * 0.25f * ext.x, lightY, c.z + (u.y - 0.5f) * 0.25f * ext.z);
    set.rays.push_back(spawnRayTo(sp.pos, sp.posError, sp.geomNormal, target));
  }
  return set;
}

// ---------------------------------------------------------------------------------------------

struct BuildResult {
  std::string name;
  std::vector<double> seconds;
  uint64_t bytes = 0;      ///< memory held by the built structure
  uint64_t peakBytes = 0;  ///< peak during the build (Embree: monitor; HBVH: not tracked)
};

/// HBVH build time over Embree MEDIUM's (builds[0] and [1]), the median of the repetitions'
/// ratios (each repetition builds both in turn).
double buildRatio(const std::vector<BuildResult>& builds) {
  std::vector<double> r;
  for (size_t i = 0; i < builds[0].seconds.size() && i < builds[1].seconds.size(); ++i)
    r.push_back(builds[0].seconds[i] / builds[1].seconds[i]);
  return median(r);
}

struct SetResult {
  std::string name;
  size_t rays = 0;
  double hitFraction = 0.0;  ///< by the reference (Embree MEDIUM)
  std::vector<std::vector<double>> seconds;  ///< per tracer, per repetition
  size_t hitMismatches = 0;  ///< hit/miss (or occluded/unoccluded) differs HBVH vs Embree MEDIUM
  size_t tMismatches = 0;    ///< both hit, relative |t difference| > 1e-4
};

/// The HBVH's rays per second over Embree MEDIUM's: the median of the repetitions' ratios, each
/// measured side by side (traceInterleaved on one thread); 0 where one was not timed (--only).
double hbvhRatio(const SetResult& r) {
  const std::vector<double>& h = r.seconds[0];
  const std::vector<double>& e = r.seconds[1];
  if (h.empty() || h.size() != e.size()) return 0.0;
  std::vector<double> ratios;
  for (size_t i = 0; i < h.size(); ++i) ratios.push_back(e[i] / h[i]);
  return median(ratios);
}

int run(const Options& opt) {
  const ThreadLimit limit(opt.threads);
  std::printf("hbvh_bench: mesh %s, threads %d, reps %d, light %s\n", opt.meshPath.c_str(), limit.threads(), opt.reps,
              opt.light.c_str());

  // Load the mesh in its file's coordinates.
  Timer loadTimer;
  const TriangleMesh mesh = loadMesh(opt.meshPath);
  const Bounds3 box = mesh.bounds();
  std::printf("loaded %zu vertices, %zu triangles in %.2f s\n", mesh.positions.size(), mesh.triangles.size(),
              loadTimer.seconds());

  // Embree device with the default configuration and a memory monitor.
  RTCDevice device = rtcNewDevice(std::getenv("VOXCONE_EMBREE_CONFIG"));
  if (!device) throw Error("rtcNewDevice failed");
  rtcSetDeviceErrorFunction(device, embreeError, nullptr);
  EmbreeMemory embreeMem;
  rtcSetDeviceMemoryMonitorFunction(device, embreeMemoryMonitor, &embreeMem);

  struct EmbreeVariant {
    std::string name;
    RTCBuildQuality quality;
    RTCSceneFlags flags = RTC_SCENE_FLAG_NONE;
  };
  std::vector<EmbreeVariant> variants = {{"Embree MEDIUM", RTC_BUILD_QUALITY_MEDIUM}};
  if (opt.allQualities) {
    variants.push_back({"Embree LOW", RTC_BUILD_QUALITY_LOW});
    variants.push_back({"Embree HIGH", RTC_BUILD_QUALITY_HIGH});
  }
  // Embree's robust mode: a conservative box test and a watertight triangle test, as the HBVH's
  // kernels (the reference, Embree MEDIUM, runs neither).
  if (opt.embreeRobust) variants.push_back({"Embree robust", RTC_BUILD_QUALITY_MEDIUM, RTC_SCENE_FLAG_ROBUST});

  // Builds. Each builder builds once untimed, then they take turns (who goes first alternating)
  // and each reports the median of buildReps: memory a process touches for the first time is
  // slow to fault in (on a VM, the host backs it then; on this machine a 10M-triangle build
  // spent over a second there), and whoever built first paid for it while the next reused the
  // pages it freed.
  std::vector<BuildResult> builds = {{"HBVH", {}, 0, 0}};
  std::unique_ptr<Hbvh> bvh;
  std::vector<std::unique_ptr<EmbreeScene>> scenes(variants.size());
  const auto buildHbvh = [&](bool timed) {
    bvh.reset();
    Timer t;
    bvh = std::make_unique<Hbvh>(mesh.positions, mesh.triangles, opt.hbvh);
    if (timed) builds[0].seconds.push_back(t.seconds());
    builds[0].bytes = bvh->stats().bytes;
  };
  for (const EmbreeVariant& v : variants) builds.push_back({v.name, {}, 0, 0});
  const auto buildEmbree = [&](size_t k, bool timed) {
    scenes[k].reset();
    const int64_t base = embreeMem.current.load();
    embreeMem.resetPeak();
    Timer t;
    scenes[k] = std::make_unique<EmbreeScene>(device, mesh, variants[k].quality, variants[k].flags);
    if (timed) builds[k + 1].seconds.push_back(t.seconds());
    builds[k + 1].bytes = uint64_t(embreeMem.current.load() - base);
    builds[k + 1].peakBytes = uint64_t(embreeMem.peak.load() - base);
  };
  buildHbvh(false);
  for (size_t k = 0; k < variants.size(); ++k) buildEmbree(k, false);
  for (int i = 0; i < opt.buildReps; ++i) {
    if (i % 2 == 0) buildHbvh(true);
    for (size_t k = 0; k < variants.size(); ++k) buildEmbree(k, true);
    if (i % 2 == 1) buildHbvh(true);
  }
  const HbvhStats& hs = bvh->stats();

  std::vector<Tracer> tracers = {hbvhTracer(*bvh)};
  for (size_t i = 0; i < variants.size(); ++i) tracers.push_back(embreeTracer(variants[i].name, scenes[i]->scene()));

  // Ray sets.
  Timer genTimer;
  std::vector<RaySet> sets;
  sets.push_back(primaryRays(box, mesh.positions, opt.resolution));
  const size_t count = sets[0].rays.size();
  sets.push_back(incoherentRays(box, count, opt.seed));
  const std::vector<SurfacePoint> pts = primaryHits(*bvh, mesh, sets[0]);
  sets.push_back(secondaryRays(pts, opt.seed));
  sets.push_back(occlusionRays(pts, box, opt.seed, opt.light == "below"));
  std::printf("generated ray sets in %.2f s (primary hits: %zu of %zu)\n\n", genTimer.seconds(), pts.size(), count);

  // Trace: one untimed pass (warm-up and verification), then interleaved timed repetitions.
  std::vector<SetResult> results;
  for (const RaySet& set : sets) {
    if (!opt.set.empty() && set.name != opt.set) continue;
    SetResult sr;
    sr.name = set.name;
    sr.rays = set.rays.size();
    sr.seconds.resize(tracers.size());
    std::vector<std::vector<float>> out(tracers.size());
    for (size_t k = 0; k < tracers.size(); ++k)
      traceAll(set.occlusion ? tracers[k].occluded : tracers[k].intersect, set.rays, out[k], limit.threads());
    // Verify HBVH (0) against Embree MEDIUM (1).
    size_t hits = 0;
    for (size_t i = 0; i < set.rays.size(); ++i) {
      const float a = out[0][i], b = out[1][i];
      const bool hitA = set.occlusion ? a != 0.0f : a != kInf;
      const bool hitB = set.occlusion ? b != 0.0f : b != kInf;
      hits += hitB;
      if (hitA != hitB)
        ++sr.hitMismatches;
      else if (!set.occlusion && hitA && std::fabs(a - b) > 1e-4f * std::max(std::fabs(b), 1e-20f))
        ++sr.tMismatches;
    }
    sr.hitFraction = sr.rays ? double(hits) / double(sr.rays) : 0.0;
#ifdef VOXCONE_HBVH_COUNTERS
    if (limit.threads() == 1) {
      hbvhCounters() = {};
      traceAll(set.occlusion ? tracers[0].occluded : tracers[0].intersect, set.rays, out[0], 1);
      const double n = double(set.rays.size());
      std::printf("counters %-11s nodes/ray %.2f leaves/ray %.2f packets/ray %.2f\n", set.name.c_str(),
                  hbvhCounters().nodes / n, hbvhCounters().leaves / n, hbvhCounters().packets / n);
    }
#endif
    std::vector<float> scratch;
    const auto fn = [&](size_t k) -> const BlockFn& { return set.occlusion ? tracers[k].occluded : tracers[k].intersect; };
    for (int rep = 0; rep < opt.reps; ++rep) {
      if (limit.threads() == 1 && opt.only.empty()) {
        std::vector<const BlockFn*> fns;
        for (size_t k = 0; k < tracers.size(); ++k) fns.push_back(&fn(k));
        const std::vector<double> s = traceInterleaved(fns, set.rays, scratch);
        for (size_t k = 0; k < tracers.size(); ++k) sr.seconds[k].push_back(s[k]);
        continue;
      }
      for (size_t k = 0; k < tracers.size(); ++k)
        if (opt.only.empty() || opt.only == tracers[k].name)
          sr.seconds[k].push_back(traceAll(fn(k), set.rays, scratch, limit.threads()));
    }
    results.push_back(std::move(sr));
  }

  // Tables.
  std::printf("HBVH settings: bins %d, max leaf %d, sphere area ratio %.2f | nodes %llu (quantized %llu), leaves %llu, "
              "sphere nodes %llu, avg leaf %.2f, max depth %d, SAH %.2f\n",
              opt.hbvh.binCount, opt.hbvh.maxLeafSize, double(opt.hbvh.sphereAreaRatio),
              (unsigned long long)hs.nodes, (unsigned long long)hs.quantizedNodes, (unsigned long long)hs.leaves,
              (unsigned long long)hs.sphereNodes,
              hs.avgLeafSize, hs.maxDepth, hs.sahCost);
  std::printf("HBVH boxes padded by %.3g (2^%d of the largest coordinate, %.3g); origins within %.3g take the "
              "one-FMA box test\n",
              double(hs.boxPadding), int(std::lround(std::log2(Hbvh::kBoxPaddingRelative))),
              double(maxComponent(glm::max(glm::abs(bvh->bounds().lo), glm::abs(bvh->bounds().hi)))),
              double(hs.paddedOriginBound));
  const HbvhLayout layout = bvh->layout();
  std::printf("HBVH layout: %llu of %llu leaves below QNodes follow them; distinct vertices a leaf triangle %.2f "
              "(%llu leaves over 16)\n",
              (unsigned long long)layout.leavesAfterTheirQNode, (unsigned long long)layout.leavesBelowQNodes,
              double(layout.leafDistinctVertices) / double(std::max<uint64_t>(layout.leafTriangles, 1)),
              (unsigned long long)layout.leavesOver16Vertices);
  std::printf("\n%-14s %10s %10s %12s\n", "build", "time ms", "MiB", "peak MiB");
  for (const BuildResult& b : builds) {
    char peak[32] = "-";
    if (b.peakBytes) std::snprintf(peak, sizeof(peak), "%.1f", b.peakBytes / kMiB);
    std::printf("%-14s %10.1f %10.1f %12s\n", b.name.c_str(), 1e3 * median(b.seconds), b.bytes / kMiB, peak);
  }
  std::printf("HBVH / Embree MEDIUM build time: %.3f (median of the repetitions' ratios)\n", buildRatio(builds));
  std::printf("\n%-11s %8s %7s %13s %15s %7s %12s %12s\n", "set", "rays", "hit %", "HBVH Mrays/s", "Embree Mrays/s",
              "ratio", "hit/miss", "t > 1e-4");
  for (const SetResult& r : results) {
    const double h = r.rays / median(r.seconds[0]) * 1e-6, e = r.rays / median(r.seconds[1]) * 1e-6;
    char tm[32] = "-";
    if (r.name != "occlusion") std::snprintf(tm, sizeof(tm), "%zu", r.tMismatches);
    std::printf("%-11s %8zu %7.1f %13.3f %15.3f %7.3f %12zu %12s\n", r.name.c_str(), r.rays, 100.0 * r.hitFraction, h,
                e, hbvhRatio(r), r.hitMismatches, tm);
  }
  if (tracers.size() > 2) {
    std::printf("\n%-11s", "Mrays/s");
    for (const Tracer& t : tracers) std::printf(" %14s", t.name.c_str());
    std::printf("\n");
    for (const SetResult& r : results) {
      std::printf("%-11s", r.name.c_str());
      for (size_t k = 0; k < tracers.size(); ++k) std::printf(" %14.3f", r.rays / median(r.seconds[k]) * 1e-6);
      std::printf("\n");
    }
  }
  std::printf("\n(Embree MEDIUM is the reference; mismatches count rays of each set, hit/miss = the two disagree on "
              "hit or miss, t > 1e-4 = both hit but the distances differ by more than 1e-4 relative.)\n");

  // JSON.
  if (!opt.jsonPath.empty()) {
    nlohmann::json j;
    j["mesh"] = opt.meshPath;
    j["vertices"] = mesh.positions.size();
    j["triangles"] = mesh.triangles.size();
    j["threads"] = limit.threads();
    j["reps"] = opt.reps;
    j["light"] = opt.light;
    j["seed"] = opt.seed;
    j["resolution"] = opt.resolution;
    j["hbvh_settings"] = {{"bin_count", opt.hbvh.binCount},
                          {"max_leaf_size", opt.hbvh.maxLeafSize},
                          {"sphere_area_ratio", opt.hbvh.sphereAreaRatio},
                          {"sphere_test_cost", opt.hbvh.sphereTestCost},
                          {"traversal_cost", opt.hbvh.traversalCost},
                          {"intersection_cost", opt.hbvh.intersectionCost},
                          {"leaf_test_width", opt.hbvh.leafTestWidth},
                          {"quantize_below", opt.hbvh.quantizeBelow}};
    j["hbvh_stats"] = hs.toJson();
    j["build_ratio"] = buildRatio(builds);
    for (const BuildResult& b : builds)
      j["builds"].push_back({{"name", b.name},
                             {"seconds_median", median(b.seconds)},
                             {"seconds", b.seconds},
                             {"bytes", b.bytes},
                             {"peak_bytes", b.peakBytes}});
    for (const SetResult& r : results) {
      nlohmann::json s = {{"name", r.name},
                          {"rays", r.rays},
                          {"hit_fraction", r.hitFraction},
                          {"hit_mismatches", r.hitMismatches},
                          {"t_mismatches", r.tMismatches}};
      for (size_t k = 0; k < tracers.size(); ++k)
        s["tracers"].push_back({{"name", tracers[k].name},
                                {"mrays_per_second", r.rays / median(r.seconds[k]) * 1e-6},
                                {"seconds", r.seconds[k]}});
      s["ratio"] = hbvhRatio(r);
      j["sets"].push_back(s);
    }
    std::ofstream f(opt.jsonPath);
    if (!f) throw Error("cannot write " + opt.jsonPath);
    f << j.dump(2) << "\n";
    std::printf("wrote %s\n", opt.jsonPath.c_str());
  }

  tracers.clear();
  scenes.clear();
  rtcReleaseDevice(device);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options opt;
  CLI::App app{"HBVH vs Embree 3: build time, memory and single-ray throughput on one mesh"};
  app.add_option("--mesh", opt.meshPath, "mesh file (.ply or .obj)");
  app.add_option("-t,--threads", opt.threads, "threads for builds and tracing (0 = all)")->check(CLI::NonNegativeNumber);
  app.add_option("--reps", opt.reps, "timed repetitions per ray set (median reported)")->check(CLI::PositiveNumber);
  app.add_option("--build-reps", opt.buildReps, "builds per accelerator (median reported)")->check(CLI::PositiveNumber);
  app.add_option("--resolution", opt.resolution, "primary rays: N x N; other sets follow")->check(CLI::PositiveNumber);
  app.add_option("--seed", opt.seed, "seed of the ray sets");
  app.add_option("--sphere-ratio", opt.hbvh.sphereAreaRatio, "HbvhBuildSettings::sphereAreaRatio (0 = plain AABB)");
  app.add_option("--sphere-cost", opt.hbvh.sphereTestCost, "HbvhBuildSettings::sphereTestCost (0 = by area alone)");
  app.add_option("--leaf", opt.hbvh.maxLeafSize, "HbvhBuildSettings::maxLeafSize")->check(CLI::Range(1, 64));
  app.add_option("--bins", opt.hbvh.binCount, "HbvhBuildSettings::binCount")->check(CLI::Range(2, 256));
  app.add_option("--traversal-cost", opt.hbvh.traversalCost, "HbvhBuildSettings::traversalCost")
      ->check(CLI::PositiveNumber);
  app.add_option("--leaf-test-width", opt.hbvh.leafTestWidth, "HbvhBuildSettings::leafTestWidth")->check(CLI::IsMember({4, 8}));
  app.add_option("--quantize-below", opt.hbvh.quantizeBelow, "HbvhBuildSettings::quantizeBelow (0 = no quantized nodes)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--intersection-cost", opt.hbvh.intersectionCost, "HbvhBuildSettings::intersectionCost")
      ->check(CLI::PositiveNumber);
  app.add_flag("--all-qualities", opt.allQualities, "also build and trace Embree LOW and HIGH");
  app.add_option("--light", opt.light, "shadow rays towards a light above the mesh (the default) or below it")
      ->check(CLI::IsMember({"above", "below"}));
  app.add_flag("--embree-robust", opt.embreeRobust,
               "also build and trace Embree MEDIUM in robust mode (RTC_SCENE_FLAG_ROBUST: conservative boxes, "
               "watertight triangles, as the HBVH)");
  app.add_option("--json", opt.jsonPath, "write the results as JSON to this path");
  app.add_option("--set", opt.set, "trace only this ray set (primary, incoherent, secondary, occlusion)");
  app.add_option("--only", opt.only,
                 "time only this tracer (\"HBVH\", \"Embree MEDIUM\"), e.g. under perf record; the untimed "
                 "verification pass still runs every tracer");
  CLI11_PARSE(app, argc, argv);
  try {
    return run(opt);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "hbvh_bench: %s\n", e.what());
    return 1;
  }
}

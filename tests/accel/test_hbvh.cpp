// The HBVH, the plain BVH and the kd-tree against brute force: closest hits and occlusion on
// over a million random rays over several meshes, including rays aimed exactly at vertices and
// edges.

#include "voxcone/accel/embree_accel.h"
#include "voxcone/accel/hbvh.h"
#include "voxcone/accel/kdtree.h"
#include "voxcone/accel/triangle.h"
#include "voxcone/core/error.h"
#include "voxcone/core/parallel.h"
#include "voxcone/core/rng.h"
#include "voxcone/core/sampling.h"
#include "voxcone/scene/scene.h"

#include "../support/test_scenes.h"
#include "../../src/accel/triangle4_sse.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <tbb/parallel_for.h>

#include <atomic>
#include <cstdio>
#include <cstring>
#include <functional>
#include <sstream>

namespace voxcone {
namespace {

struct Soup {
  std::string name;
  std::vector<Vec3> pos;
  std::vector<UVec3> tris;
};

std::optional<Hit> bruteIntersect(const Soup& s, const Ray& ray) {
  const WatertightRay wr(ray.dir);
  Hit best;
  bool found = false;
  float tMax = ray.tMax;
  for (uint32_t i = 0; i < s.tris.size(); ++i) {
    float t, b1, b2;
    if (intersectTriangleWatertight(ray.origin, wr, s.pos[s.tris[i].x], s.pos[s.tris[i].y], s.pos[s.tris[i].z],
                                    ray.tMin, tMax, t, b1, b2)) {
      tMax = t;
      best = {t, i, b1, b2};
      found = true;
    }
  }
  return found ? std::optional<Hit>(best) : std::nullopt;
}

Soup sphereSoup(int subdiv) {
  const Scene sc = test::furnaceScene(0.5f, 1.0f, 0.0f, subdiv);
  return {"sphere", sc.positions, sc.triangles};
}

Soup randomSoup(int n, uint64_t seed) {
  Soup s{"random", {}, {}};
  Rng rng(seed, 0);
  for (int i = 0; i < n; ++i) {
    const Vec3 c(rng.uniform() * 10 - 5, rng.uniform() * 10 - 5, rng.uniform() * 10 - 5);
    const float size = 0.05f + 1.5f * rng.uniform() * rng.uniform();
    for (int k = 0; k < 3; ++k) s.pos.push_back(c + size * (Vec3(rng.uniform(), rng.uniform(), rng.uniform()) - 0.5f));
    s.tris.push_back(UVec3(3 * i, 3 * i + 1, 3 * i + 2));
  }
  return s;
}

/// A wavy grid of quads (shared edges and vertices everywhere).
Soup gridSoup(int n) {
  Soup s{"grid", {}, {}};
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i)
      s.pos.emplace_back(float(i), 0.3f * std::sin(0.7f * i) * std::cos(0.5f * j), float(j));
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const uint32_t a = j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
      s.tris.push_back({a, b, d});
      s.tris.push_back({a, d, c});
    }
  return s;
}

Soup cornellSoup() {
  const Scene sc = loadScene(test::sourceDir() + "/data/scenes/cornell-box.json");
  return {"cornell", sc.positions, sc.triangles};
}

/// Random rays: from points in an enlarged bounding box (or from `origin`) towards random points,
/// vertices and edge points of the mesh.
Ray makeRay(const Soup& s, const Bounds3& b, Rng& rng, const std::optional<Vec3>& origin = std::nullopt) {
  const Vec3 ext = b.diagonal() * 1.5f + Vec3(1e-3f);
  Vec3 o = b.center() + (Vec3(rng.uniform(), rng.uniform(), rng.uniform()) - 0.5f) * ext;
  if (origin) o = *origin;
  Vec3 target;
  const float kind = rng.uniform();
  const UVec3& t = s.tris[std::min<size_t>(size_t(rng.uniform() * s.tris.size()), s.tris.size() - 1)];
  if (kind < 0.25f) {
    target = s.pos[t[std::min(2, int(rng.uniform() * 3))]];  // exactly a vertex
  } else if (kind < 0.5f) {
    const float u = rng.uniform();
    target = (1 - u) * s.pos[t.x] + u * s.pos[t.y];  // on an edge
  } else if (kind < 0.75f) {
    target = b.center() + (Vec3(rng.uniform(), rng.uniform(), rng.uniform()) - 0.5f) * ext;
  } else {
    const Vec2 bc = sampleUniformTriangle(rng.uniform2());
    target = (1 - bc.x - bc.y) * s.pos[t.x] + bc.x * s.pos[t.y] + bc.y * s.pos[t.z];
  }
  Ray r;
  r.origin = o;
  r.dir = target - o;
  if (glm::length(r.dir) == 0.0f) r.dir = Vec3(0, 0, 1);
  if (rng.uniform() < 0.5f) r.dir = glm::normalize(r.dir);
  r.tMax = rng.uniform() < 0.2f ? 0.5f * kInf : kInf;
  return r;
}

/// True when two hit distances are the same surface point: rays through a shared vertex or edge
/// hit several triangles whose distances differ by float rounding of their own vertices, and
/// brute force and the HBVH may keep different ones.
bool sameHitDistance(float a, float b) { return std::fabs(a - b) <= 1e-5f * std::max(1.0f, std::fabs(a)); }

/// The structures under test, each with settings that stress it.
struct Variant {
  std::string name;
  std::function<std::unique_ptr<Accel>(const Soup&)> build;
  /// The HBVH keeps the smaller triangle id of hits at the same distance, as bruteIntersect does,
  /// so it finds the very same hit; the kd-tree the first it visits (sameHitDistance).
  bool exact = true;
};

constexpr int kAllQuantized = 1 << 30, kNoneQuantized = 0;  ///< HbvhBuildSettings::quantizeBelow

std::vector<Variant> variants() {
  auto hbvh = [](float ratio, int leaf, Hbvh::Simd simd = Hbvh::hostSimd(), int quantizeBelow = kAllQuantized) {
    return [=](const Soup& s) {
      HbvhBuildSettings settings;
      settings.sphereAreaRatio = ratio;
      settings.sphereTestCost = 0.0f;  // by area alone: spheres wherever the ratio allows
      settings.maxLeafSize = leaf;
      settings.quantizeBelow = quantizeBelow;
      settings.quantizeMinTriangles = 0;
      auto bvh = std::make_unique<Hbvh>(s.pos, s.tris, settings);
      if (ratio > 1.0f && s.tris.size() > 8) {
        EXPECT_GT(bvh->stats().sphereNodes, 0u) << s.name;
      }
      bvh->setSimd(simd);
      return std::unique_ptr<Accel>(std::move(bvh));
    };
  };
  auto kd = [](int bins, int leaf, float isect) {
    return [=](const Soup& s) {
      KdTreeBuildSettings settings;
      settings.binCount = bins;
      settings.maxLeafSize = leaf;
      settings.intersectionCost = isect;
      return std::unique_ptr<Accel>(std::make_unique<KdTree>(s.pos, s.tris, settings));
    };
  };
  // A plain AABB BVH, the hybrid, spheres on every node with small leaves, each with every node
  // but the root quantized; the hybrid with full nodes only, and with full nodes above quantized
  // ones (as large scenes are built by default); the kd-tree as built by default and pushed to
  // deep trees of many straddling references.
  // The HBVH with the host's kernels (the widest the CPU runs) and, where those are not SSE,
  // once more with the SSE kernels forced; where the host runs AVX-512, the hybrid once with
  // AVX2.
  const Hbvh::Simd host = Hbvh::hostSimd();
  std::vector<Variant> v = {{"bvh", hbvh(0.0f, 8)},
                            {"hbvh", hbvh(1.0f, 8)},
                            {"hbvh-all-spheres", hbvh(100.0f, 2)},
                            {"hbvh-full-nodes", hbvh(1.0f, 8, host, kNoneQuantized)},
                            {"hbvh-all-spheres-full-nodes", hbvh(100.0f, 2, host, kNoneQuantized)},
                            {"hbvh-quantized-below-64", hbvh(1.0f, 8, host, 64)},
                            {"kdtree", kd(32, 8, 1.0f), false},
                            {"kdtree-deep", kd(7, 1, 20.0f), false}};
  if (host != Hbvh::Simd::Sse42) {
    v.push_back({"hbvh-sse4.2", hbvh(1.0f, 8, Hbvh::Simd::Sse42)});
    v.push_back({"hbvh-all-spheres-sse4.2", hbvh(100.0f, 2, Hbvh::Simd::Sse42)});
    v.push_back({"hbvh-full-nodes-sse4.2", hbvh(1.0f, 8, Hbvh::Simd::Sse42, kNoneQuantized)});
  }
  if (host == Hbvh::Simd::Avx512) v.push_back({"hbvh-avx2", hbvh(1.0f, 8, Hbvh::Simd::Avx2)});
  return v;
}

TEST(Accel, EveryStructureMatchesBruteForceOnOverAMillionRays) {
  const std::vector<Soup> soups = {sphereSoup(3), randomSoup(400, 7), gridSoup(14), cornellSoup()};
  constexpr int kRaysPerMesh = 1 << 18;
  uint64_t total = 0, hits = 0;
  for (const Soup& s : soups) {
    Bounds3 b;
    for (const Vec3& p : s.pos) b.extend(p);
    // Rays and their brute-force closest hits, computed once per mesh.
    std::vector<Ray> rays(kRaysPerMesh);
    std::vector<std::optional<Hit>> ref(kRaysPerMesh);
    tbb::parallel_for(0, kRaysPerMesh / 1024, [&](int block) {
      Rng rng(42, uint64_t(block));
      for (int i = block * 1024; i < (block + 1) * 1024; ++i) {
        rays[i] = makeRay(s, b, rng);
        ref[i] = bruteIntersect(s, rays[i]);
      }
    });
    for (const auto& h : ref) hits += h.has_value();
    total += kRaysPerMesh;
    for (const Variant& v : variants()) {
      const std::unique_ptr<Accel> accel = v.build(s);
      std::atomic<uint64_t> closest{0}, occlusion{0};
      tbb::parallel_for(0, kRaysPerMesh / 1024, [&](int block) {
        Rng rng(43, uint64_t(block));
        for (int i = block * 1024; i < (block + 1) * 1024; ++i) {
          const Ray& r = rays[i];
          const auto got = accel->intersect(r);
          if (ref[i].has_value() != got.has_value() ||
              (got && (v.exact ? got->t != ref[i]->t || got->triangle != ref[i]->triangle
                               : !sameHitDistance(ref[i]->t, got->t)))) {
            ++closest;
          }
          // Occlusion up to tOcc: something lies in (tMin, tOcc) exactly when the closest hit does.
          const float tOcc = ref[i] ? ref[i]->t * (0.5f + rng.uniform()) : r.tMax;
          if (!v.exact && ref[i] && sameHitDistance(ref[i]->t, tOcc)) continue;
          if (accel->occluded(r, tOcc) != (ref[i] && ref[i]->t < tOcc)) ++occlusion;
        }
      });
      EXPECT_EQ(closest.load(), 0u) << s.name << " " << v.name;
      EXPECT_EQ(occlusion.load(), 0u) << s.name << " " << v.name;
    }
  }
  EXPECT_GE(total, 1000000u);
  EXPECT_GT(hits, total / 4);  // the ray sets really hit the meshes
}

TEST(Accel, EmbreeAgreesWithBruteForceButForEdges) {
  // --accel embree: Embree 3's own (non-watertight) test, so only nearly every ray: a ray through
  // a shared edge or vertex may slip between the triangles, which the HBVH never lets happen.
  if (!embreeAvailable()) GTEST_SKIP() << "built without Embree";
  for (const Soup& s : {sphereSoup(3), randomSoup(400, 7), cornellSoup()}) {
    Bounds3 b;
    for (const Vec3& p : s.pos) b.extend(p);
    const std::unique_ptr<Accel> embree = buildAccel("embree", s.pos, s.tris);
    EXPECT_EQ(embree->kind(), "embree");
    EXPECT_GT(embree->bytes(), 0u);
    Rng rng(44, 0);
    int rays = 0, closest = 0, occlusion = 0, sameTriangle = 0, roughBarycentrics = 0;
    for (int i = 0; i < 20000; ++i, ++rays) {
      // Towards points well inside triangles, or anywhere in the box (no vertex or edge aims).
      const Vec3 ext = b.diagonal() * 1.5f + Vec3(1e-3f);
      Ray r;
      r.origin = b.center() + (Vec3(rng.uniform(), rng.uniform(), rng.uniform()) - 0.5f) * ext;
      const UVec3& t = s.tris[std::min<size_t>(size_t(rng.uniform() * s.tris.size()), s.tris.size() - 1)];
      const Vec2 bc = 0.1f + 0.8f * sampleUniformTriangle(rng.uniform2());
      const Vec3 target = rng.uniform() < 0.7f ? (1 - bc.x - bc.y) * s.pos[t.x] + bc.x * s.pos[t.y] + bc.y * s.pos[t.z]
                                               : b.center() + (Vec3(rng.uniform(), rng.uniform(), rng.uniform()) - 0.5f) * ext;
      r.dir = target - r.origin;
      if (glm::length(r.dir) == 0.0f) r.dir = Vec3(0, 0, 1);
      const auto ref = bruteIntersect(s, r);
      const auto got = embree->intersect(r);
      if (ref.has_value() != got.has_value() || (got && !sameHitDistance(ref->t, got->t))) ++closest;
      if (got && ref && got->triangle == ref->triangle) {
        // Embree's barycentrics (Moeller-Trumbore from v0's edges) lose digits at grazing
        // angles on the random soup's small triangles: off by more than 1e-3 on a few hits.
        const float off = std::max(std::fabs(got->b1 - ref->b1), std::fabs(got->b2 - ref->b2));
        EXPECT_LT(off, 0.05f);
        ++sameTriangle;
        roughBarycentrics += off > 1e-3f;
      }
      if (embree->occluded(r) != ref.has_value()) ++occlusion;
    }
    // Measured: at most 31 of 20,000 (the random soup's grazing rays).
    EXPECT_LE(closest, rays / 200) << s.name;
    EXPECT_LE(occlusion, rays / 200) << s.name;
    EXPECT_GT(sameTriangle, rays / 10) << s.name;
    EXPECT_LE(roughBarycentrics, sameTriangle / 100) << s.name;
  }
  // Invalid triangles are left out and ids still name the caller's triangles.
  const std::vector<Vec3> pos = {Vec3(NAN), Vec3(1), Vec3(2), Vec3(-1, -1, 2), Vec3(1, -1, 2), Vec3(0, 1, 2)};
  const std::unique_ptr<Accel> embree = buildAccel("embree", pos, {{0, 1, 2}, {3, 4, 5}, {0, 9, 1}});
  const auto h = embree->intersect(Ray());
  ASSERT_TRUE(h);
  EXPECT_EQ(h->triangle, 1u);
  EXPECT_FLOAT_EQ(h->t, 2.0f);
}

TEST(Accel, ClosedMeshIsWatertightThroughVerticesAndEdges) {
  // Every ray from the centre of a closed sphere must hit it, also when aimed exactly at a
  // vertex or an edge point (no crack between triangles).
  const Soup s = sphereSoup(4);
  for (const Variant& v : variants()) {
  const std::unique_ptr<Accel> bvh = v.build(s);
  Rng rng(3, 0);
  int misses = 0, rays = 0;
  for (size_t t = 0; t < s.tris.size(); ++t) {
    const UVec3& tri = s.tris[t];
    const Vec3 targets[4] = {s.pos[tri.x], 0.5f * (s.pos[tri.x] + s.pos[tri.y]),
                             s.pos[tri.y] + rng.uniform() * (s.pos[tri.z] - s.pos[tri.y]), s.pos[tri.z]};
    for (const Vec3& target : targets) {
      Ray r;
      r.origin = Vec3(0.01f, -0.02f, 0.015f);
      r.dir = target - r.origin;
      ++rays;
      if (!bvh->intersect(r)) ++misses;
      if (!bvh->occluded(r)) ++misses;
    }
  }
  EXPECT_EQ(misses, 0) << v.name << ": of " << rays << " rays";
  }
}

TEST(Hbvh, EachQNodesLeavesFollowIt) {
  // The block layout: a QNode's leaves lie right after it in m_blocks, in child order (a ray
  // finds them in the QNode's page), checked by a walk over the built arrays; the walk also
  // finds every node and leaf the stats count, and no reference past its array.
  const Soup s = randomSoup(20000, 23);
  for (const int quantizeBelow : {0, 64, 1 << 30}) {
    HbvhBuildSettings settings;
    settings.quantizeBelow = quantizeBelow;
    settings.quantizeMinTriangles = 0;
    const Hbvh bvh(s.pos, s.tris, settings);
    const HbvhLayout l = bvh.layout();
    EXPECT_EQ(l.nodes + l.qnodes, bvh.stats().nodes) << quantizeBelow;
    EXPECT_EQ(l.qnodes, bvh.stats().quantizedNodes) << quantizeBelow;
    EXPECT_EQ(l.leaves, bvh.stats().leaves) << quantizeBelow;
    EXPECT_EQ(l.outOfBounds, 0u) << quantizeBelow;
    EXPECT_EQ(l.leavesAfterTheirQNode, l.leavesBelowQNodes) << quantizeBelow;
    // Every triangle lies in one leaf; those of the random soup share no vertex.
    EXPECT_EQ(l.leafTriangles, bvh.stats().triangles) << quantizeBelow;
    EXPECT_EQ(l.leafDistinctVertices, 3 * l.leafTriangles) << quantizeBelow;
    if (quantizeBelow == 0) {
      EXPECT_EQ(l.qnodes, 0u);
    } else {
      EXPECT_GT(l.leavesBelowQNodes, l.leaves / 2) << quantizeBelow;  // most leaves hang below QNodes
    }
  }
  // A grid's triangles share their vertices: a leaf of up to eight holds far fewer than three
  // distinct vertices a triangle, never more than 16.
  const Soup g = gridSoup(40);
  const HbvhLayout gl = Hbvh(g.pos, g.tris).layout();
  EXPECT_EQ(gl.leafTriangles, g.tris.size());
  EXPECT_LT(gl.leafDistinctVertices, 2 * gl.leafTriangles);
  EXPECT_GT(gl.leafDistinctVertices, gl.leafTriangles / 2);
  EXPECT_EQ(gl.leavesOver16Vertices, 0u);
}

TEST(Hbvh, StatsAreConsistent) {
  const Soup s = randomSoup(5000, 11);
  const Hbvh bvh(s.pos, s.tris);
  const HbvhStats& st = bvh.stats();
  EXPECT_EQ(st.triangles, 5000u);
  EXPECT_EQ(st.binaryNodes, 2 * st.leaves - 1);  // the binary tree is full; collapsing keeps its leaves
  // Each 8-wide node replaces 1-7 binary inner nodes: leaves - 1 = sum over nodes of (children - 1).
  EXPECT_GE(st.nodes, (st.leaves - 1 + Hbvh::kWidth - 2) / (Hbvh::kWidth - 1));
  EXPECT_LE(st.nodes, st.leaves - 1);
  EXPECT_GT(st.maxDepth, 3);
  EXPECT_LE(st.maxDepth, 40);
  EXPECT_GT(st.sahCost, 1.0);
  EXPECT_GT(st.bytes, 5000u * 40u);
  EXPECT_LE(st.avgLeafSize, 8.0);
  // A mesh this small keeps full nodes by default; quantized, every node but the root takes 128
  // bytes instead of 256, and the tree is the same.
  EXPECT_EQ(st.quantizedNodes, 0u);
  HbvhBuildSettings quantized;
  quantized.quantizeBelow = 1 << 30;
  quantized.quantizeMinTriangles = 0;
  const Hbvh qbvh(s.pos, s.tris, quantized);
  EXPECT_EQ(qbvh.stats().quantizedNodes, st.nodes - 1);
  EXPECT_EQ(qbvh.stats().nodes, st.nodes);
  EXPECT_EQ(qbvh.stats().leaves, st.leaves);
  EXPECT_EQ(st.bytes - qbvh.stats().bytes, (st.nodes - 1) * 128u);
  // Quantized below 64 triangles: the lowest levels only.
  quantized.quantizeBelow = 64;
  const Hbvh lowBvh(s.pos, s.tris, quantized);
  EXPECT_GT(lowBvh.stats().quantizedNodes, st.nodes / 2);
  EXPECT_LT(lowBvh.stats().quantizedNodes, st.nodes - 1);
}

TEST(Accel, BuildIsIdenticalAtAnyThreadCount) {
  const Soup s = randomSoup(20000, 5);
  Bounds3 bounds;
  for (const Vec3& p : s.pos) bounds.extend(p);
  for (const std::string& kind : accelKinds()) {
    nlohmann::json stats[2];
    std::vector<std::optional<Hit>> hits[2];
    for (int threads : {1, 2}) {
      ThreadLimit limit(threads);
      const std::unique_ptr<Accel> accel = buildAccel(kind, s.pos, s.tris);
      stats[threads - 1] = accel->statsJson();
      stats[threads - 1].erase("build_seconds");
      Rng rng(9, 0);
      for (int i = 0; i < 2000; ++i) hits[threads - 1].push_back(accel->intersect(makeRay(s, bounds, rng)));
    }
    EXPECT_EQ(stats[0], stats[1]) << kind;  // nodes, leaves, depth, SAH cost, bytes
    ASSERT_EQ(hits[0].size(), hits[1].size());
    for (size_t i = 0; i < hits[0].size(); ++i) {
      ASSERT_EQ(hits[0][i].has_value(), hits[1][i].has_value()) << kind;
      if (hits[0][i]) {
        EXPECT_EQ(hits[0][i]->t, hits[1][i]->t);
        EXPECT_EQ(hits[0][i]->triangle, hits[1][i]->triangle);
      }
    }
  }
}

TEST(Accel, ShortSegmentsSeeAWallNearTheirStart) {
  // A 4.67 x 2.73 m wall in the plane x = 0 (the face of a held-out two-rooms scene's 4 mm
  // wall) and a 1.1 cm segment, given as an unnormalized direction (t in [0, 1]), that crosses
  // it 3 mm from its start, at t = 0.2919 (a double-precision test's figure). The watertight
  // test's error bound, taken as PBRT writes it (z scaled by 1 / dir[kz]), came out at
  // t = 0.35 for this ray and every structure dropped the hit; scaled by 10, the same direction
  // found it. Bound for the ray scaled to |dir[kz]| = 1, it holds at any length.
  const std::vector<Vec3> pos = {Vec3(0, 0, 0), Vec3(0, 0, 4.672923f), Vec3(0, 2.728718f, 4.672923f),
                                 Vec3(0, 2.728718f, 0)};
  const std::vector<UVec3> tris = {{0, 1, 2}, {0, 2, 3}};
  const Vec3 origin(-0.00116769f, 0.0170464f, 0.96379f), dir(0.004f, -0.00748207f, -0.00770438f);
  for (const std::string& kind : accelKinds()) {
    const std::unique_ptr<Accel> accel = buildAccel(kind, pos, tris);
    for (float scale : {1.0f, 1e-2f, 10.0f}) {
      Ray r;
      r.origin = origin;
      r.dir = dir * scale;
      r.tMax = 1.0f / scale;
      EXPECT_TRUE(accel->occluded(r)) << kind << " scale " << scale;
      const std::optional<Hit> h = accel->intersect(r);
      ASSERT_TRUE(h) << kind << " scale " << scale;
      EXPECT_NEAR(h->t * scale, 0.291923f, 1e-4f) << kind;
    }
  }
}

TEST(Accel, EmptyAndDegenerateInput) {
  for (const std::string& kind : accelKinds()) {
    const std::unique_ptr<Accel> empty = buildAccel(kind, std::vector<Vec3>{}, std::vector<UVec3>{});
    Ray r;
    EXPECT_FALSE(empty->intersect(r)) << kind;
    EXPECT_FALSE(empty->occluded(r)) << kind;
    // Degenerate (zero-area) and NaN triangles never hit and never break the build.
    std::vector<Vec3> pos = {Vec3(0), Vec3(0), Vec3(0), Vec3(NAN), Vec3(1), Vec3(2), Vec3(-1, -1, 2), Vec3(1, -1, 2),
                             Vec3(0, 1, 2)};
    std::vector<UVec3> tris = {{0, 1, 2}, {3, 4, 5}, {6, 7, 8}};
    const std::unique_ptr<Accel> accel = buildAccel(kind, pos, tris);
    EXPECT_EQ(accel->kind(), kind);
    const auto h = accel->intersect(r);
    ASSERT_TRUE(h) << kind;
    EXPECT_EQ(h->triangle, 2u);
    EXPECT_FLOAT_EQ(h->t, 2.0f);
  }
  EXPECT_THROW(buildAccel("octree", std::vector<Vec3>{}, std::vector<UVec3>{}), SettingsError);
}

TEST(Hbvh, RaysFromBeforeTheirOriginAreTracedFromIt) {
  // The kernels order box distances as integers, which holds for tMin >= 0: a negative tMin
  // is traced from the origin (as Embree's tnear), in every kernel, closest hit and occlusion.
  // Squares at z = -1 (behind the origin) and z = 2, 3 (in front), the ray along +z.
  std::vector<Vec3> pos;
  std::vector<UVec3> tris;
  for (float z : {-1.0f, 2.0f, 3.0f}) {
    const uint32_t b = uint32_t(pos.size());
    for (Vec3 p : {Vec3(-1, -1, z), Vec3(1, -1, z), Vec3(1, 1, z), Vec3(-1, 1, z)}) pos.push_back(p);
    tris.push_back({b, b + 1, b + 2});
    tris.push_back({b, b + 2, b + 3});
  }
  const std::vector<Hbvh::Simd> kernels = Hbvh::runnableSimds();
  for (Hbvh::Simd simd : kernels) {
    Hbvh bvh(pos, tris);
    bvh.setSimd(simd);
    Ray r;
    r.origin = Vec3(0.1f, 0.2f, 0.0f);
    r.dir = Vec3(0, 0, 1);
    r.tMin = -5.0f;
    const auto h = bvh.intersect(r);
    ASSERT_TRUE(h) << Hbvh::simdName(simd);
    EXPECT_FLOAT_EQ(h->t, 2.0f) << Hbvh::simdName(simd);
    EXPECT_FALSE(bvh.occluded(r, 1.5f)) << Hbvh::simdName(simd);  // only the square behind lies before 1.5
    EXPECT_TRUE(bvh.occluded(r, 2.5f)) << Hbvh::simdName(simd);
    r.dir = Vec3(0, 0, -1);  // towards the square behind: in front now
    const auto back = bvh.intersect(r);
    ASSERT_TRUE(back) << Hbvh::simdName(simd);
    EXPECT_FLOAT_EQ(back->t, 1.0f) << Hbvh::simdName(simd);
    r.tMin = -0.0f;  // -0 orders below every negative float as an integer: traced from +0 too
    const auto fromMinusZero = bvh.intersect(r);
    ASSERT_TRUE(fromMinusZero) << Hbvh::simdName(simd);
    EXPECT_FLOAT_EQ(fromMinusZero->t, 1.0f) << Hbvh::simdName(simd);
  }
}

TEST(Hbvh, SimdKernelsFindTheSameHitsBitForBit) {
  // The AVX2, AVX-512 and SSE kernels run the same operations in the same order, so renders do
  // not depend on the machine's instruction set: every hit, distance and barycentric equal.
  const std::vector<Hbvh::Simd> kernels = Hbvh::runnableSimds();
  if (kernels.size() < 2) GTEST_SKIP() << "this CPU runs no AVX2 kernels";
  for (const Hbvh::Simd wide : kernels) {
    if (wide == Hbvh::Simd::Sse42) continue;
    for (const Soup& s : {sphereSoup(3), randomSoup(3000, 13), cornellSoup()}) {
      Bounds3 b;
      for (const Vec3& p : s.pos) b.extend(p);
      for (const auto& [ratio, quantizeBelow] : {std::pair{1.0f, 0}, {100.0f, 0}, {1.0f, 1 << 30}, {100.0f, 1 << 30}}) {
        HbvhBuildSettings settings;
        settings.sphereAreaRatio = ratio;
        settings.sphereTestCost = 0.0f;
        settings.quantizeBelow = quantizeBelow;
        settings.quantizeMinTriangles = 0;
        Hbvh avx(s.pos, s.tris, settings), sse(s.pos, s.tris, settings);
        avx.setSimd(wide);
        sse.setSimd(Hbvh::Simd::Sse42);
        Rng rng(17, 0);
        int hits = 0, differ = 0;
        for (int i = 0; i < 50000; ++i) {
          const Ray r = makeRay(s, b, rng);
          const auto a = avx.intersect(r), c = sse.intersect(r);
          hits += a.has_value();
          if (a.has_value() != c.has_value() ||
              (a && (a->t != c->t || a->triangle != c->triangle || a->b1 != c->b1 || a->b2 != c->b2)))
            ++differ;
          const float tOcc = a ? a->t : r.tMax;
          if (avx.occluded(r, tOcc) != sse.occluded(r, tOcc)) ++differ;
        }
        EXPECT_EQ(differ, 0) << Hbvh::simdName(wide) << " " << s.name << " sphere ratio " << ratio
                             << " quantized below " << quantizeBelow;
        EXPECT_GT(hits, 5000) << s.name;
      }
    }
  }
}

TEST(Hbvh, PaddedAndRobustBoxTestsFindTheBruteForceHits) {
  // Rays from origins within the padded bound take the one-FMA box test, whose rounding is an
  // absolute error the boxes' padding covers; rays from farther take the robust one. Meshes small
  // and far from the origin (where that error is largest against the boxes), rays towards
  // vertices and edges, origins on both sides of the bound: every kernel finds brute force's
  // very hit (distance and triangle) and its occlusion, with full and quantized nodes.
  const std::vector<Hbvh::Simd> kernels = Hbvh::runnableSimds();
  for (const Soup& mesh : {randomSoup(600, 31), gridSoup(16)}) {
    Soup s = mesh;
    for (Vec3& p : s.pos) p = Vec3(1000.0f, -700.0f, 3000.0f) + 0.01f * p;
    Bounds3 b;
    for (const Vec3& p : s.pos) b.extend(p);
    for (const int quantizeBelow : {kNoneQuantized, kAllQuantized}) {
      HbvhBuildSettings settings;
      settings.quantizeBelow = quantizeBelow;
      settings.quantizeMinTriangles = 0;
      Hbvh bvh(s.pos, s.tris, settings);
      const float bound = bvh.stats().paddedOriginBound;
      const float largest = maxComponent(glm::max(glm::abs(b.lo), glm::abs(b.hi)));
      EXPECT_EQ(bvh.stats().boxPadding, float(largest * Hbvh::kBoxPaddingRelative + 0x1p-68));
      EXPECT_GT(bound, 4.7f * largest);  // 4.8 times the largest coordinate
      EXPECT_LT(bound, 4.8f * largest);
      for (Hbvh::Simd simd : kernels) {
        bvh.setSimd(simd);
        Rng rng(37, 0);
        int padded = 0, robust = 0, hits = 0, differ = 0;
        for (int i = 0; i < 30000; ++i) {
          std::optional<Vec3> origin;
          if (i % 2) {  // a point on a cube's face, 0.9 .. 1.1 times the bound: either side of it
            Vec3 o = (2.0f * Vec3(rng.uniform(), rng.uniform(), rng.uniform()) - 1.0f);
            o[std::min(2, int(3.0f * rng.uniform()))] = rng.uniform() < 0.5f ? -1.0f : 1.0f;
            origin = o * (bound * (0.9f + 0.2f * rng.uniform()));
          }
          const Ray r = makeRay(s, b, rng, origin);
          (maxComponent(glm::abs(r.origin)) <= bound ? padded : robust) += 1;
          const auto ref = bruteIntersect(s, r), got = bvh.intersect(r);
          hits += ref.has_value();
          if (ref.has_value() != got.has_value() || (got && (got->t != ref->t || got->triangle != ref->triangle)))
            ++differ;
          const float tOcc = ref ? ref->t * (0.5f + rng.uniform()) : r.tMax;
          if (bvh.occluded(r, tOcc) != (ref && ref->t < tOcc)) ++differ;
        }
        EXPECT_EQ(differ, 0) << s.name << " " << Hbvh::simdName(simd) << " quantized below " << quantizeBelow;
        EXPECT_GT(padded, 15000);
        EXPECT_GT(robust, 5000);
        EXPECT_GT(hits, 5000) << s.name;
      }
    }
  }
}

TEST(Hbvh, QuantizedNodesFindWhatFullNodesFind) {
  // The same tree with full and with quantized child boxes: the quantized boxes contain the full
  // ones as the kernels compute them, so every ray finds the same closest hit (up to the float
  // ties of a shared edge or vertex, whose winner follows the order of the visit, as against
  // brute force) and the same occlusion. The meshes as they are and moved far from the origin
  // and shrunk, where a plane's rounding (origin + q scale) is large against a quantization
  // step; both kernels, with and without spheres.
  const std::vector<Hbvh::Simd> kernels = Hbvh::runnableSimds();
  for (const Soup& mesh : {randomSoup(3000, 21), gridSoup(40), cornellSoup()}) {
    for (const float scale : {1.0f, 0.05f}) {
      Soup s = mesh;
      if (scale != 1.0f) {
        for (Vec3& p : s.pos) p = Vec3(300.0f, -70.0f, 1100.0f) + scale * p;
        s.name += "-far-small";
      }
      Bounds3 b;
      for (const Vec3& p : s.pos) b.extend(p);
      for (float ratio : {1.0f, 100.0f}) {
        HbvhBuildSettings settings;
        settings.sphereAreaRatio = ratio;
        settings.sphereTestCost = 0.0f;
        settings.quantizeBelow = 0;
        Hbvh full(s.pos, s.tris, settings);
        settings.quantizeBelow = 1 << 30;
        settings.quantizeMinTriangles = 0;
        Hbvh quantized(s.pos, s.tris, settings);
        ASSERT_EQ(quantized.stats().quantizedNodes, quantized.stats().nodes - 1);
        for (Hbvh::Simd simd : kernels) {
          full.setSimd(simd);
          quantized.setSimd(simd);
          Rng rng(23, 0);
          int hits = 0, differ = 0;
          for (int i = 0; i < 100000; ++i) {
            const Ray r = makeRay(s, b, rng);
            const auto a = full.intersect(r), q = quantized.intersect(r);
            hits += a.has_value();
            if (a.has_value() != q.has_value() || (a && !sameHitDistance(a->t, q->t))) ++differ;
            const float tOcc = a ? a->t * (0.5f + rng.uniform()) : r.tMax;
            if (a && sameHitDistance(a->t, tOcc)) continue;
            if (full.occluded(r, tOcc) != quantized.occluded(r, tOcc)) ++differ;
          }
          EXPECT_EQ(differ, 0) << s.name << " sphere ratio " << ratio << " " << Hbvh::simdName(simd);
          EXPECT_GT(hits, 10000) << s.name;
        }
      }
    }
  }
}

TEST(Hbvh, SpheresAreKeptWhereTheSahSaysTheyPay) {
  // A sphere is kept only where (A_box - A_sphere) * subtree cost > A_box * sphereTestCost:
  // free tests keep every sphere the area ratio allows, dearer ones fewer, and one dearer than
  // any subtree none; the trees are the same but for their spheres.
  const Soup s = sphereSoup(4);
  const auto spheres = [&](float ratio, float cost) {
    HbvhBuildSettings settings;
    settings.sphereAreaRatio = ratio;
    settings.sphereTestCost = cost;
    const Hbvh bvh(s.pos, s.tris, settings);
    return std::make_pair(bvh.stats().sphereNodes, bvh.stats().nodes);
  };
  const auto byArea = spheres(100.0f, 0.0f), cheap = spheres(100.0f, 0.001f), dearer = spheres(100.0f, 0.05f),
             dear = spheres(100.0f, 1e6f);
  EXPECT_GT(byArea.first, cheap.first);  // a cost at all: only spheres smaller than their box
  EXPECT_GT(cheap.first, dearer.first);
  EXPECT_GT(dearer.first, 0u);
  EXPECT_EQ(dear.first, 0u);
  EXPECT_EQ(byArea.second, dear.second);
  EXPECT_EQ(spheres(0.0f, 0.0f).first, 0u);  // ratio 0: a plain BVH whatever the cost
  HbvhBuildSettings bad;
  bad.sphereTestCost = -1.0f;
  EXPECT_THROW(Hbvh(s.pos, s.tris, bad), SettingsError);
}

TEST(Hbvh, PacketRayConstantsAreTheWatertightRays) {
  // The packet test makes the watertight test's permutation and shear itself (RayTri4); every
  // lane equals the scalar test only if they are WatertightRay's, bit for bit, and it reads the
  // rows of those axes: ties between axes, signed zeros, each octant, random directions.
  std::vector<Vec3> dirs;
  const float values[] = {0.0f, -0.0f, 1.0f, -1.0f, 0.5f, -0.5f, 1e-30f, -3.0f};
  for (float x : values)
    for (float y : values)
      for (float z : values)
        if (x != 0.0f || y != 0.0f || z != 0.0f) dirs.emplace_back(x, y, z);
  Rng rng(7, 0);
  for (int i = 0; i < 10000; ++i) dirs.push_back(sampleUniformSphere(rng.uniform2()) * (0.1f + 10.0f * rng.uniform()));
  for (const Vec3& d : dirs) {
    Ray r;
    r.dir = d;
    const WatertightRay wr(d);
    const sse42::RayTri4 rt(r);
    ASSERT_EQ(rt.kx, wr.kx) << d.x << " " << d.y << " " << d.z;
    ASSERT_EQ(rt.ky, wr.ky);
    ASSERT_EQ(rt.kz, wr.kz);
    ASSERT_EQ(std::memcmp(&rt.sx, &wr.sx, sizeof(float)), 0);
    ASSERT_EQ(std::memcmp(&rt.sy, &wr.sy, sizeof(float)), 0);
    ASSERT_EQ(std::memcmp(&rt.sz, &wr.sz, sizeof(float)), 0);
    ASSERT_EQ(std::memcmp(&rt.dz, &wr.dz, sizeof(float)), 0);
    // The rows the packet test reads (kPacketRowBytes): axis k's row is k rows of 4 or 8 floats in.
    const sse42::RayTriLanes rl(r);
    const int k[3] = {wr.kx, wr.ky, wr.kz};
    for (int a = 0; a < 3; ++a) {
      ASSERT_EQ(rl.rowBytes[0][a], k[a] * 4 * int64_t(sizeof(float)));
      ASSERT_EQ(rl.rowBytes[1][a], k[a] * 8 * int64_t(sizeof(float)));
    }
  }
}

TEST(Hbvh, AvxKernelsShareNoInlineCodeWithTheBaseline) {
  // The AVX2 and AVX-512 kernels' object files may define only functions of their own namespace
  // (voxcone::avx2, voxcone::avx512): an inline function of another namespace compiled there
  // with wider instructions could be the copy the linker keeps for every caller, and crash the
  // binary on a CPU without them.
  std::vector<std::pair<std::string, std::string>> objects;  // path, namespace
#ifdef VOXCONE_AVX2_OBJECT
  objects.emplace_back(VOXCONE_AVX2_OBJECT, " voxcone::avx2::");
#endif
#ifdef VOXCONE_AVX512_OBJECT
  objects.emplace_back(VOXCONE_AVX512_OBJECT, " voxcone::avx512::");
#endif
  if (objects.empty()) GTEST_SKIP() << "built without AVX2 kernels";
  for (const auto& [object, ns] : objects) {
    const std::string cmd = "nm -C --defined-only -g '" + object + "' 2>&1";
    FILE* p = popen(cmd.c_str(), "r");
    ASSERT_NE(p, nullptr);
    std::string out;
    char buf[4096];
    while (fgets(buf, sizeof(buf), p)) out += buf;
    const int rc = pclose(p);
    if (rc != 0) GTEST_SKIP() << "nm failed: " << out;
    int defined = 0;
    std::istringstream lines(out);
    for (std::string line; std::getline(lines, line);) {
      // Type descriptions (UBSan's function-type checks emit them) are data, the same whatever
      // the instruction set.
      if (line.empty() || line.find(" typeinfo") != std::string::npos) continue;
      ++defined;
      EXPECT_NE(line.find(ns), std::string::npos) << object << ": " << line;
    }
    EXPECT_GE(defined, 4) << object;  // hbvhIntersect, hbvhOccluded and their Lean forms
  }
}

TEST(KdTree, StatsAreConsistent) {
  const Soup s = randomSoup(5000, 11);
  const KdTree kd(s.pos, s.tris);
  const KdTreeStats& st = kd.stats();
  EXPECT_EQ(st.triangles, 5000u);
  EXPECT_EQ(st.nodes, 2 * st.leaves - 1);  // every inner node has two children
  EXPECT_GE(st.references, st.triangles);   // straddling triangles are referenced per leaf
  EXPECT_LT(st.references, 4 * st.triangles);
  EXPECT_GT(st.emptyLeaves, 0u);            // the empty-space bonus cuts off empty cells
  EXPECT_GT(st.maxDepth, 8);
  EXPECT_LE(st.maxDepth, 8 + int(1.3 * std::log2(5000.0)) + 2);
  EXPECT_GT(st.sahCost, 1.0);
  // Packets: at least references / 4, at most one partial packet per leaf more.
  const uint64_t packetBytes = st.bytes - st.nodes * sizeof(KdTree::Node);
  EXPECT_GE(packetBytes, (st.references + 3) / 4 * sizeof(Triangle4));
  EXPECT_LE(packetBytes, (st.references / 4 + st.leaves) * sizeof(Triangle4));
}

}  // namespace
}  // namespace voxcone

// The photon kd-tree against brute force.

#include "voxcone/core/rng.h"
#include "voxcone/photon/photon_kdtree.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <limits>

namespace voxcone {
namespace {

/// The k nearest points with dist2 <= maxDist2, sorted by (distance, index).
std::vector<KdNeighbor> bruteForce(const std::vector<Vec3>& pts, const Vec3& q, int k, float maxDist2) {
  std::vector<KdNeighbor> all;
  for (uint32_t i = 0; i < pts.size(); ++i) {
    const Vec3 d = q - pts[i];
    const float d2 = glm::dot(d, d);
    if (d2 <= maxDist2) all.push_back({i, d2});
  }
  std::sort(all.begin(), all.end(), [](const KdNeighbor& a, const KdNeighbor& b) {
    return a.dist2 < b.dist2 || (a.dist2 == b.dist2 && a.index < b.index);
  });
  if (all.size() > size_t(k)) all.resize(k);
  return all;
}

TEST(PhotonKdTree, MatchesBruteForce) {
  Rng rng(7, 0);
  std::vector<Vec3> pts(2000);
  for (Vec3& p : pts) p = Vec3(rng.uniform(), rng.uniform(), rng.uniform()) * Vec3(2.0f, 1.0f, 0.5f);
  const PhotonKdTree tree(pts);
  ASSERT_EQ(tree.size(), pts.size());
  std::vector<KdNeighbor> got;
  size_t checked = 0;
  for (int qi = 0; qi < 500; ++qi) {
    // Queries cover the box and a margin outside it.
    const Vec3 q = (Vec3(rng.uniform(), rng.uniform(), rng.uniform()) * 1.2f - 0.1f) * Vec3(2.0f, 1.0f, 0.5f);
    for (int k : {1, 7, 50}) {
      for (float maxDist2 : {std::numeric_limits<float>::infinity(), 0.01f}) {
        const std::vector<KdNeighbor> want = bruteForce(pts, q, k, maxDist2);
        ASSERT_EQ(tree.knn(q, k, maxDist2, got), want.size());
        for (size_t i = 0; i < want.size(); ++i) {
          ASSERT_EQ(got[i].index, want[i].index) << "query " << qi << " k " << k;
          ASSERT_EQ(got[i].dist2, want[i].dist2);
        }
        if (maxDist2 == std::numeric_limits<float>::infinity()) {
          EXPECT_EQ(got.size(), size_t(k));
        }
        checked += want.size();
      }
    }
  }
  EXPECT_GT(checked, 500u * 58u);
}

TEST(PhotonKdTree, EmptyAndDuplicatePoints) {
  std::vector<KdNeighbor> got;
  EXPECT_EQ(PhotonKdTree().knn(Vec3(0.0f), 5, 1.0f, got), 0u);
  // Equal points: ties are broken by index.
  const std::vector<Vec3> pts(10, Vec3(1.0f, 2.0f, 3.0f));
  const PhotonKdTree tree(pts);
  ASSERT_EQ(tree.knn(Vec3(1.0f, 2.0f, 3.5f), 4, 1.0f, got), 4u);
  for (uint32_t i = 0; i < 4; ++i) EXPECT_EQ(got[i].index, i);
  EXPECT_EQ(tree.knn(Vec3(1.0f, 2.0f, 5.0f), 4, 1.0f, got), 0u);
}

}  // namespace
}  // namespace voxcone

// The cells the camera's gathers read photons from.

#include "voxcone/photon/seen_region.h"

#include "voxcone/accel/accel.h"
#include "voxcone/core/sampling.h"
#include "voxcone/scene/bsdf.h"
#include "voxcone/scene/scene.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

namespace voxcone {

namespace {
/// Delta bounces followed from the camera before giving up on a ray.
constexpr int kMaxDeltaBounces = 8;

/// The first non-delta surface along `ray` and the strongest lobe of each mirror or glass met
/// (`ray` ends as the last segment followed); false where none is met.
bool firstDiffuseHit(const Scene& scene, const Accel& accel, Ray& ray, SurfaceHit& sh) {
  for (int bounce = 0; bounce <= kMaxDeltaBounces; ++bounce) {
    if (!intersectSurface(scene, accel, ray, sh)) return false;
    const Material& m = scene.materials[sh.material];
    if (!m.isDelta()) return true;
    const Frame frame(sh.shadingNormal);
    DeltaLobe lobes[2];
    const int n = bsdfDeltaLobes(m, frame.toLocal(-glm::normalize(ray.dir)), lobes);
    if (n == 0) return false;
    const int best = n == 2 && maxComponent(lobes[1].weight) > maxComponent(lobes[0].weight) ? 1 : 0;
    ray = spawnRay(sh.position, sh.positionError, sh.geomNormal, frame.toWorld(lobes[best].wi));
  }
  return false;
}

/// For each ray of a `raysX` x `raysY` grid of camera rays over a `width` x `height` image (its
/// rows in parallel): visit(row, hit, nullptr) at its first non-delta hit, then visit(row, hit,
/// &g) for each of `gathers` stratified cosine-distributed rays from the side the camera sees
/// that meets a surface g (0 gathers: none).
template <typename Visit>
void walkGathers(const Scene& scene, const Accel& accel, int width, int height, int raysX, int raysY, int gathers,
                 Visit&& visit) {
  const int strata = gathers > 0 ? std::max(1, int(std::lround(std::sqrt(double(gathers))))) : 0;
  tbb::parallel_for(0, raysY, [&](int y) {
    for (int x = 0; x < raysX; ++x) {
      Ray ray = scene.camera.generateRay((float(x) + 0.5f) / float(raysX) * float(width),
                                         (float(y) + 0.5f) / float(raysY) * float(height), width, height);
      SurfaceHit sh;
      if (!firstDiffuseHit(scene, accel, ray, sh)) continue;
      visit(y, sh, nullptr);
      const Vec3 ng = glm::dot(sh.geomNormal, ray.dir) < 0.0f ? sh.geomNormal : -sh.geomNormal;
      const Frame frame(ng);
      for (int i = 0; i < strata * strata; ++i) {
        const Vec2 u((float(i % strata) + 0.5f) / float(strata), (float(i / strata) + 0.5f) / float(strata));
        const Ray g = spawnRay(sh.position, sh.positionError, ng, frame.toWorld(sampleCosineHemisphere(u)));
        SurfaceHit gh;
        if (intersectSurface(scene, accel, g, gh)) visit(y, sh, &gh);
      }
    }
  });
}
}  // namespace

uint64_t SeenRegion::keyOf(const Vec3& worldPos) const {
  // 21 bits per axis; the grid starts at the scene's lower corner, and points outside clamp.
  const Vec3 q = (worldPos - m_origin) / m_cellSize;
  uint64_t key = 0;
  for (int a = 0; a < 3; ++a) {
    const double c = std::clamp(double(std::floor(q[a])), 0.0, double((1 << 21) - 1));
    key = (key << 21) | uint64_t(c);
  }
  return key;
}

SeenRegion::SeenRegion(const Scene& scene, const Accel& accel, int width, int height, float cellSize, int raysX,
                       int raysY, int gathers)
    : m_cellSize(cellSize), m_origin(scene.bounds().lo) {
  std::vector<std::vector<uint64_t>> rows(size_t(std::max(raysY, 0)));
  walkGathers(scene, accel, width, height, raysX, raysY, gathers,
              [&](int y, const SurfaceHit& hit, const SurfaceHit* gathered) {
                rows[size_t(y)].push_back(keyOf(gathered ? gathered->position : hit.position));
              });
  for (const std::vector<uint64_t>& r : rows) m_keys.insert(m_keys.end(), r.begin(), r.end());
  std::sort(m_keys.begin(), m_keys.end());
  m_keys.erase(std::unique(m_keys.begin(), m_keys.end()), m_keys.end());
}

double SeenRegion::meanGatherDistance(const Scene& scene, const Accel& accel, int width, int height, int raysX,
                                      int raysY, int gathers) {
  std::vector<double> sums(size_t(std::max(raysY, 0)), 0.0), counts(sums.size(), 0.0);
  walkGathers(scene, accel, width, height, raysX, raysY, gathers,
              [&](int y, const SurfaceHit& hit, const SurfaceHit* gathered) {
                if (!gathered) return;
                sums[size_t(y)] += double(glm::length(gathered->position - hit.position));
                counts[size_t(y)] += 1.0;
              });
  double sum = 0.0, count = 0.0;
  for (size_t i = 0; i < sums.size(); ++i) sum += sums[i], count += counts[i];
  return count > 0.0 ? sum / count : 0.0;
}

void SeenRegion::dilate() {
  std::vector<uint64_t> grown;
  grown.reserve(m_keys.size() * 27);
  constexpr uint64_t kAxis = (uint64_t(1) << 21) - 1;
  for (const uint64_t k : m_keys) {
    const int64_t c[3] = {int64_t(k >> 42), int64_t((k >> 21) & kAxis), int64_t(k & kAxis)};
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int64_t x = c[0] + dx, y = c[1] + dy, z = c[2] + dz;
          if (x < 0 || y < 0 || z < 0 || x > int64_t(kAxis) || y > int64_t(kAxis) || z > int64_t(kAxis)) continue;
          grown.push_back(uint64_t(x) << 42 | uint64_t(y) << 21 | uint64_t(z));
        }
  }
  std::sort(grown.begin(), grown.end());
  grown.erase(std::unique(grown.begin(), grown.end()), grown.end());
  m_keys = std::move(grown);
}

bool SeenRegion::contains(const Vec3& worldPos) const {
  return std::binary_search(m_keys.begin(), m_keys.end(), keyOf(worldPos));
}

uint64_t SeenRegion::count(const std::vector<Photon>& photons, int minBounces) const {
  uint64_t n = 0;
  for (const Photon& p : photons) n += p.bounces >= minBounces && contains(p.position) ? 1 : 0;
  return n;
}

}  // namespace voxcone

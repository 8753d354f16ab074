// The cells the camera's gathers read photons from.

#include "voxcone/photon/seen_region.h"

#include "voxcone/accel/accel.h"
#include "voxcone/core/sampling.h"
#include "voxcone/photon/photon_radiance.h"
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
/// rows in parallel): visit(row, hit, nullptr, side) at its first non-delta hit, then
/// visit(row, hit, &g, side) for each of `gathers` stratified cosine-distributed rays from the
/// side the camera sees that meets a surface g (0 gathers: none); `side` is the geometric normal
/// of the point visited turned towards the ray that found it.
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
      const Vec3 ng = glm::dot(sh.geomNormal, ray.dir) < 0.0f ? sh.geomNormal : -sh.geomNormal;
      visit(y, sh, nullptr, ng);
      const Frame frame(ng);
      for (int i = 0; i < strata * strata; ++i) {
        const Vec2 u((float(i % strata) + 0.5f) / float(strata), (float(i / strata) + 0.5f) / float(strata));
        const Ray g = spawnRay(sh.position, sh.positionError, ng, frame.toWorld(sampleCosineHemisphere(u)));
        SurfaceHit gh;
        if (intersectSurface(scene, accel, g, gh))
          visit(y, sh, &gh, glm::dot(gh.geomNormal, g.dir) < 0.0f ? gh.geomNormal : -gh.geomNormal);
      }
    }
  });
}
}  // namespace

uint64_t SeenRegion::keyOf(const Vec3& worldPos, int facing) const {
  // 20 bits per axis, then the facing (3 bits); the grid starts at the scene's lower corner, and
  // points outside clamp.
  const Vec3 q = (worldPos - m_origin) / m_cellSize;
  uint64_t key = 0;
  for (int a = 0; a < 3; ++a) {
    const double c = std::clamp(double(std::floor(q[a])), 0.0, double(kAxisMask));
    key = (key << kAxisBits) | uint64_t(c);
  }
  return key << 3 | uint64_t(facing);
}

int SeenRegion::facingOf(const Vec3& n) {
  int axis = 0;
  for (int a = 1; a < 3; ++a)
    if (std::fabs(n[a]) > std::fabs(n[axis])) axis = a;
  return 2 * axis + (n[axis] < 0.0f ? 1 : 0);
}

SeenRegion::SeenRegion(const Scene& scene, const Accel& accel, int width, int height, float cellSize, int raysX,
                       int raysY, int gathers)
    : m_cellSize(cellSize), m_origin(scene.bounds().lo) {
  std::vector<std::vector<uint64_t>> rows(size_t(std::max(raysY, 0)));
  walkGathers(scene, accel, width, height, raysX, raysY, gathers,
              [&](int y, const SurfaceHit& hit, const SurfaceHit* gathered, const Vec3& side) {
                // Every facing the side leans into by kFacingSlack: a photon's shading normal may
                // lean to another axis than the geometric one seen here.
                const Vec3& p = gathered ? gathered->position : hit.position;
                for (int a = 0; a < 3; ++a)
                  if (std::fabs(side[a]) >= kFacingSlack) rows[size_t(y)].push_back(keyOf(p, 2 * a + (side[a] < 0.0f ? 1 : 0)));
              });
  for (const std::vector<uint64_t>& r : rows) m_keys.insert(m_keys.end(), r.begin(), r.end());
  std::sort(m_keys.begin(), m_keys.end());
  m_keys.erase(std::unique(m_keys.begin(), m_keys.end()), m_keys.end());
}

double SeenRegion::meanGatherDistance(const Scene& scene, const Accel& accel, int width, int height, int raysX,
                                      int raysY, int gathers) {
  std::vector<double> sums(size_t(std::max(raysY, 0)), 0.0), counts(sums.size(), 0.0);
  walkGathers(scene, accel, width, height, raysX, raysY, gathers,
              [&](int y, const SurfaceHit& hit, const SurfaceHit* gathered, const Vec3&) {
                if (!gathered) return;
                sums[size_t(y)] += double(glm::length(gathered->position - hit.position));
                counts[size_t(y)] += 1.0;
              });
  double sum = 0.0, count = 0.0;
  for (size_t i = 0; i < sums.size(); ++i) sum += sums[i], count += counts[i];
  return count > 0.0 ? sum / count : 0.0;
}

Sphere SeenRegion::readSphere(const Scene& scene, const Accel& accel, int width, int height, double quantile, int raysX,
                              int raysY, int gathers) {
  std::vector<std::vector<Vec3>> rows(size_t(std::max(raysY, 0)));
  walkGathers(scene, accel, width, height, raysX, raysY, gathers,
              [&](int y, const SurfaceHit& hit, const SurfaceHit* gathered, const Vec3&) {
                rows[size_t(y)].push_back(gathered ? gathered->position : hit.position);
              });
  std::vector<Vec3> points;
  for (const std::vector<Vec3>& r : rows) points.insert(points.end(), r.begin(), r.end());
  Sphere s;
  if (points.empty()) return s;
  std::vector<float> axis(points.size());
  for (int a = 0; a < 3; ++a) {
    for (size_t i = 0; i < points.size(); ++i) axis[i] = points[i][a];
    std::nth_element(axis.begin(), axis.begin() + std::ptrdiff_t(axis.size() / 2), axis.end());
    s.center[a] = axis[axis.size() / 2];
  }
  std::vector<float> dist(points.size());
  for (size_t i = 0; i < points.size(); ++i) dist[i] = glm::length(points[i] - s.center);
  const size_t at = std::min(dist.size() - 1, size_t(std::clamp(quantile, 0.0, 1.0) * double(dist.size())));
  std::nth_element(dist.begin(), dist.begin() + std::ptrdiff_t(at), dist.end());
  s.radius = dist[at];
  return s;
}

void SeenRegion::dilate() {
  std::vector<uint64_t> grown;
  grown.reserve(m_keys.size() * 27 * 5);
  for (const uint64_t k : m_keys) {
    const uint64_t seenFacing = k & 7u, cell = k >> 3;
    const int64_t c[3] = {int64_t(cell >> (2 * kAxisBits)), int64_t((cell >> kAxisBits) & kAxisMask),
                          int64_t(cell & kAxisMask)};
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int64_t x = c[0] + dx, y = c[1] + dy, z = c[2] + dz;
          const int64_t top = int64_t(kAxisMask);
          if (x < 0 || y < 0 || z < 0 || x > top || y > top || z > top) continue;
          const uint64_t at = ((uint64_t(x) << (2 * kAxisBits)) | (uint64_t(y) << kAxisBits) | uint64_t(z)) << 3;
          // Every facing but the opposite one: a curved surface's photons lean every way but
          // away from the side seen.
          for (uint64_t f = 0; f < 6; ++f)
            if (f != (seenFacing ^ 1u)) grown.push_back(at | f);
        }
  }
  std::sort(grown.begin(), grown.end());
  grown.erase(std::unique(grown.begin(), grown.end()), grown.end());
  m_keys = std::move(grown);
}

bool SeenRegion::contains(const Vec3& worldPos, const Vec3& normal) const {
  return std::binary_search(m_keys.begin(), m_keys.end(), keyOf(worldPos, facingOf(normal)));
}

bool SeenRegion::holdsCell(const Vec3& worldPos) const {
  const uint64_t first = keyOf(worldPos, 0);
  const auto it = std::lower_bound(m_keys.begin(), m_keys.end(), first);
  return it != m_keys.end() && (*it >> 3) == (first >> 3);
}

uint64_t SeenRegion::count(const std::vector<Photon>& photons, const PhotonRadianceSettings& estimate) const {
  uint64_t n = 0;
  for (const Photon& p : photons) n += estimate.keeps(p) && contains(p.position, p.normal) ? 1 : 0;
  return n;
}

}  // namespace voxcone

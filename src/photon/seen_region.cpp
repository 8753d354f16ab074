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

std::array<uint64_t, 3> SeenRegion::cellCoords(const Vec3& worldPos) const {
  // kAxisBits per axis; the grid starts at the scene's lower corner, and points outside clamp.
  const Vec3 q = (worldPos - m_origin) / m_cellSize;
  std::array<uint64_t, 3> c;
  for (int a = 0; a < 3; ++a) c[size_t(a)] = uint64_t(std::clamp(double(std::floor(q[a])), 0.0, double(kAxisMask)));
  return c;
}

uint64_t SeenRegion::cellOf(const Vec3& worldPos) const {
  const std::array<uint64_t, 3> c = cellCoords(worldPos);
  return c[0] << (2 * kAxisBits) | c[1] << kAxisBits | c[2];
}

int SeenRegion::facingOf(const Vec3& n) {
  int axis = 0;
  for (int a = 1; a < 3; ++a)
    if (std::fabs(n[a]) > std::fabs(n[axis])) axis = a;
  return 2 * axis + (n[axis] < 0.0f ? 1 : 0);
}

void SeenRegion::mergeCells(std::vector<uint64_t>& entries) {
  std::sort(entries.begin(), entries.end());
  size_t out = 0;
  for (size_t i = 0; i < entries.size(); ++i) {
    if (out > 0 && entries[out - 1] >> kFacingBits == entries[i] >> kFacingBits) entries[out - 1] |= entries[i];
    else entries[out++] = entries[i];
  }
  entries.resize(out);
}

SeenRegion::SeenRegion(const Scene& scene, const Accel& accel, int width, int height, float cellSize, int raysX,
                       int raysY, int gathers)
    : m_cellSize(cellSize), m_origin(scene.bounds().lo) {
  std::vector<std::vector<uint64_t>> rows(size_t(std::max(raysY, 0)));
  walkGathers(scene, accel, width, height, raysX, raysY, gathers,
              [&](int y, const SurfaceHit& hit, const SurfaceHit* gathered, const Vec3& side) {
                // The facing of the side seen. (Every facing it leans into by 0.3 as well, for
                // photons whose shading normal leans to another axis, gave the same images on
                // tools/make_gltf_room.py's room, small-objects and cornell-dragon: dilate() adds
                // all but the opposite facing anyway; all three of its signed axes, 2 of 8 seeds of
                // the room beyond 10% where none was.)
                const uint64_t facings = uint64_t(1) << facingOf(side);
                rows[size_t(y)].push_back(cellOf(gathered ? gathered->position : hit.position) << kFacingBits | facings);
              });
  for (const std::vector<uint64_t>& r : rows) m_entries.insert(m_entries.end(), r.begin(), r.end());
  mergeCells(m_entries);
  index();
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
  grown.reserve(m_entries.size() * 27);
  for (const uint64_t e : m_entries) {
    const uint64_t cell = e >> kFacingBits;
    // Every facing but the opposite of a seen one: a curved surface's photons lean every way but
    // away from the side seen.
    uint64_t facings = 0;
    for (int f = 0; f < 6; ++f)
      if (e >> f & 1u) facings |= kAllFacings & ~(uint64_t(1) << (f ^ 1));
    const int64_t c[3] = {int64_t(cell >> (2 * kAxisBits)), int64_t((cell >> kAxisBits) & kAxisMask),
                          int64_t(cell & kAxisMask)};
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int64_t x = c[0] + dx, y = c[1] + dy, z = c[2] + dz;
          const int64_t top = int64_t(kAxisMask);
          if (x < 0 || y < 0 || z < 0 || x > top || y > top || z > top) continue;
          const uint64_t at = (uint64_t(x) << (2 * kAxisBits)) | (uint64_t(y) << kAxisBits) | uint64_t(z);
          grown.push_back(at << kFacingBits | facings);
        }
  }
  mergeCells(grown);
  m_entries = std::move(grown);
  index();
}

void SeenRegion::index() {
  // A dense grid of the facings over the cells' box where it is small (the photon passes' cells
  // are 1/64 of the scene's bounding sphere: at most 65^3), for lookups without a search.
  m_dense.clear();
  if (m_entries.empty()) return;
  std::array<uint64_t, 3> lo{kAxisMask, kAxisMask, kAxisMask}, hi{0, 0, 0};
  for (const uint64_t e : m_entries) {
    const uint64_t cell = e >> kFacingBits;
    const uint64_t c[3] = {cell >> (2 * kAxisBits), (cell >> kAxisBits) & kAxisMask, cell & kAxisMask};
    for (size_t a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], c[a]);
      hi[a] = std::max(hi[a], c[a]);
    }
  }
  uint64_t volume = 1;
  for (size_t a = 0; a < 3; ++a) {
    m_denseLo[a] = lo[a];
    m_denseSize[a] = hi[a] - lo[a] + 1;
    volume *= m_denseSize[a];
    if (volume > kMaxDenseCells) return;
  }
  m_dense.assign(size_t(volume), 0);
  for (const uint64_t e : m_entries) {
    const uint64_t cell = e >> kFacingBits;
    const uint64_t c[3] = {cell >> (2 * kAxisBits), (cell >> kAxisBits) & kAxisMask, cell & kAxisMask};
    m_dense[size_t(((c[0] - lo[0]) * m_denseSize[1] + (c[1] - lo[1])) * m_denseSize[2] + (c[2] - lo[2]))] =
        uint8_t(e & kAllFacings);
  }
}

uint64_t SeenRegion::facingsAt(const Vec3& worldPos) const {
  if (!m_dense.empty()) {
    const std::array<uint64_t, 3> c = cellCoords(worldPos);
    size_t at = 0;
    for (size_t a = 0; a < 3; ++a) {
      // Unsigned: a coordinate below the box wraps above its size.
      const uint64_t d = c[a] - m_denseLo[a];
      if (d >= m_denseSize[a]) return 0;
      at = at * size_t(m_denseSize[a]) + size_t(d);
    }
    return m_dense[at];
  }
  const uint64_t cell = cellOf(worldPos);
  const auto it = std::lower_bound(m_entries.begin(), m_entries.end(), cell << kFacingBits);
  return it != m_entries.end() && *it >> kFacingBits == cell ? *it & kAllFacings : 0;
}

bool SeenRegion::contains(const Vec3& worldPos, const Vec3& normal) const {
  return facingsAt(worldPos) >> facingOf(normal) & 1u;
}

bool SeenRegion::holdsCell(const Vec3& worldPos) const { return facingsAt(worldPos) != 0; }

uint64_t SeenRegion::count(const std::vector<Photon>& photons, const PhotonRadianceSettings& estimate) const {
  uint64_t n = 0;
  for (const Photon& p : photons) n += estimate.keeps(p) && contains(p.position, p.normal) ? 1 : 0;
  return n;
}

}  // namespace voxcone

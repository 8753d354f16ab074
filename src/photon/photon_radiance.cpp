// Photon density estimates at surface points, filtered to the point's own surface and side.

#include "voxcone/photon/photon_radiance.h"

#include "voxcone/accel/accel.h"
#include "voxcone/core/ray.h"
#include "voxcone/photon/seen_region.h"
#include "voxcone/scene/bsdf.h"
#include "voxcone/scene/scene.h"

#include <algorithm>
#include <cmath>
#include <cstring>

namespace voxcone {

namespace {
/// A photon's normal within 60 degrees of the point's side normal: the same surface (a corner
/// voxel's 45 degrees still counts, a perpendicular wall does not).
constexpr float kSameSurfaceCos = 0.5f;
/// Photons farther from the point's tangent plane than this fraction of the search radius lie
/// on another surface (a curved surface departs from its tangent plane by r^2 / 2R: a sphere of
/// radius 2r still passes).
constexpr float kPlaneSlab = 0.25f;
/// Both ends of a visibility segment are lifted this fraction of the search radius off their
/// surfaces along their own normals (plus the point's rounding error): clear of the surface
/// they lie on, far below any wall standing on it. The chord between two points of a convex
/// surface of radius R runs inside it beyond a distance of about 2 sqrt(2 R lift): at 1e-3 r a
/// 4 cm cup saw its own photons only within 3 mm (r = 0.1 m); at 0.05 r within 2.5 cm.
constexpr float kLift = 0.05f;
/// Where the ray that measures a lift's room starts, in lifts off the surface: clear of the
/// surface's own rounding (a photon's position carries no error bound).
constexpr float kLiftProbeStart = 1e-3f;
/// A point deeper behind x's tangent plane than this many lifts (1e-4 of the search radius,
/// far above rounding) measures its lift's room (PhotonRadiance::lifted).
constexpr float kBehindPlane = 2e-3f;
/// Probes of the disc's own surface (cover): a Vogel spiral of this many points, and where some
/// miss it (an edge, a corner), kEdgeProbes for the part's share, centroid and covariance.
constexpr int kAreaProbes = 8;
constexpr int kEdgeProbes = 32;
/// Fewer covered edge probes than this: no linear fit (a part of a few probes is a sliver whose
/// centroid and covariance are known to a probe spacing at best). A safeguard, not tuned: at 3
/// the held-out room's worst blocks (tools/make_gltf_room.py --held-out, seeds 0, 2, 5, 7) were
/// the same to 0.001.
constexpr int kMinGradientProbes = 6;
/// The part's covariance is floored by this many r^2 on each axis (a strip's width is not known
/// to better than a probe spacing: the 32 probes lie about r / 3 apart).
constexpr float kCovarianceFloor = 0.01f;
/// The linear fit changes the plain estimate by at most this factor either way: its weights go
/// negative on the far side of the part, and with few photons there the fit could reach 0 or
/// below. A safeguard, not tuned: without it the held-out room's worst blocks moved by at most
/// 0.003 (seeds 0, 2, 5, 7).
constexpr float kMaxEdgeChange = 3.0f;
/// Precomputed entries a point tries, nearest first, before it estimates in full.
constexpr int kCacheCandidates = 8;

/// A hash of a point's coordinates to [0, 1): turns the probe spiral per point, deterministically.
float pointHash(const Vec3& p) {
  uint32_t h = 2166136261u;
  for (int a = 0; a < 3; ++a) {
    uint32_t bits;
    std::memcpy(&bits, &p[a], sizeof bits);
    h = (h ^ bits) * 16777619u;
  }
  h ^= h >> 15;
  h *= 0x2c1b3c6du;
  h ^= h >> 12;
  return float(h >> 8) * 0x1p-24f;
}
}  // namespace

bool PhotonRadianceSettings::keeps(const Photon& p) const {
  // In a cell the gathers read, a photon on a side they do not see (a roof above a ceiling, a
  // wall's outer face) is of no use; in a cell they do not read, it may be (the region is a
  // sample of what the gathers reach), except the sky's straight ones (on the ground outside).
  const bool inRegion = !region || region->contains(p.position, p.normal);
  if (!inRegion && region->holdsCell(p.position)) return false;
  if (!indirectOnly || p.bounces > 0) return true;
  return p.fromEnvironment && keepsSky(p.position, p.normal);
}

bool PhotonRadianceSettings::keepsSky(const Vec3& p, const Vec3& n) const {
  return skyDirect && (!region || region->contains(p, n));
}

PhotonRadiance::PhotonRadiance(const Scene& scene, const Accel& accel, const PhotonMaps& maps,
                               const PhotonRadianceSettings& s)
    : m_scene(&scene), m_accel(&accel), m_settings(s) {
  m_photons.reserve(maps.global.size() + maps.caustic.size());
  for (const Photon& ph : maps.global)
    if (s.keeps(ph)) m_photons.push_back(ph);
  m_photons.insert(m_photons.end(), maps.caustic.begin(), maps.caustic.end());
  build();
}

PhotonRadiance::PhotonRadiance(const Scene& scene, const Accel& accel, std::vector<Photon> photons,
                               const PhotonRadianceSettings& s)
    : m_scene(&scene), m_accel(&accel), m_settings(s), m_photons(std::move(photons)) {
  m_settings.cacheStride = 0;
  build();
}

void PhotonRadiance::build() {
  const PhotonRadianceSettings& s = m_settings;
  std::vector<Vec3> positions(m_photons.size());
  for (size_t i = 0; i < m_photons.size(); ++i) positions[i] = m_photons[i].position;
  m_tree = PhotonKdTree(positions);
  if (s.cacheStride <= 1) return;
  // Every cacheStride-th photon on a diffuse surface, estimated on its own side from the other
  // photons only when a lookup first needs it (estimate()): most lookups need few of them.
  std::vector<uint32_t> at;
  for (size_t i = 0; i < m_photons.size(); i += size_t(s.cacheStride))
    if (!isBlack(m_photons[i].albedo)) at.push_back(uint32_t(i));
  m_cache.resize(at.size());
  for (size_t e = 0; e < at.size(); ++e) m_cache[e] = {m_photons[at[e]].position, m_photons[at[e]].normal};
  m_estimates = std::make_unique<CacheEstimate[]>(m_cache.size());
  m_estimateState = std::make_unique<std::atomic<uint8_t>[]>(m_cache.size());
  for (size_t e = 0; e < m_cache.size(); ++e) m_estimateState[e].store(0, std::memory_order_relaxed);
  std::vector<Vec3> cachePositions(m_cache.size());
  for (size_t e = 0; e < m_cache.size(); ++e) cachePositions[e] = m_cache[e].position;
  m_cacheTree = PhotonKdTree(cachePositions);
}

PhotonRadiance::CacheEstimate PhotonRadiance::estimate(size_t e) const {
  std::atomic<uint8_t>& state = m_estimateState[e];
  if (state.load(std::memory_order_acquire) == 2) return m_estimates[e];
  // Not made yet (or being written by another thread): make it here. Every thread makes the same
  // value, so the one that publishes it does not matter.
  const CacheEntry& c = m_cache[e];
  CacheEstimate est;
  est.irradiance = irradianceAt(c.position, Vec3(0.0f), c.normal, &est.radius, m_settings.cacheStride);
  uint8_t expected = 0;
  if (state.compare_exchange_strong(expected, 1, std::memory_order_acq_rel)) {
    m_estimates[e] = est;
    state.store(2, std::memory_order_release);
  }
  return est;
}

size_t PhotonRadiance::cacheEstimated() const {
  size_t n = 0;
  for (size_t e = 0; e < m_cache.size(); ++e) n += m_estimateState[e].load(std::memory_order_relaxed) == 2 ? 1 : 0;
  return n;
}

size_t PhotonRadiance::memoryBytes() const {
  // The tree keeps a position, an index and an axis per photon.
  return m_photons.size() * (sizeof(Photon) + sizeof(Vec3) + sizeof(uint32_t) + 1) +
         m_cache.size() * (sizeof(CacheEntry) + sizeof(CacheEstimate) + 1 + sizeof(Vec3) + sizeof(uint32_t) + 1);
}

Vec3 PhotonRadiance::lifted(const Vec3& p, const Vec3& n, const Vec3& x, const Vec3& side, float lift) const {
  if (!(glm::dot(p - x, side) < -kBehindPlane * lift)) return p + n * lift;
  Ray up;
  up.origin = p + n * (kLiftProbeStart * lift);
  up.dir = n;
  up.tMax = lift;
  const std::optional<Hit> h = m_accel->intersect(up);
  return h ? p + n * (kLiftProbeStart * lift + 0.5f * h->t) : p + n * lift;
}

PhotonRadiance::DiscCover PhotonRadiance::cover(const Vec3& x, const Vec3& side, const Vec3& from, float r,
                                                float lift, bool shape) const {
  // Probes spread uniformly over the disc (Vogel's spiral: radius sqrt((i + 1/2) / n), golden
  // angle steps), each counted when (like a photon) it is in sight of the point along the
  // surface and the surface lies under it, within the plane slab, facing the same way.
  const Frame frame(side);
  const float turn = 2.0f * kPi * pointHash(x);
  const float slab = kPlaneSlab * r;
  const auto probe = [&](int i, int probes, Vec2& at) {
    const float rho = r * std::sqrt((float(i) + 0.5f) / float(probes));
    const float phi = turn + float(i) * 2.39996323f;
    at = Vec2(rho * std::cos(phi), rho * std::sin(phi));
    const Vec3 point = x + frame.toWorld(Vec3(at, 0.0f));
    // The surface under the probe: a ray from the slab's top down through it.
    Ray down;
    down.origin = point + side * slab;
    down.dir = -side;
    down.tMax = 2.0f * slab;
    const std::optional<Hit> h = m_accel->intersect(down);
    if (!h) return false;
    const SurfaceHit under = m_scene->surfaceAt(h->triangle, h->b1, h->b2);
    const Vec3 n = glm::dot(under.geomNormal, side) >= 0.0f ? under.geomNormal : -under.geomNormal;
    if (glm::dot(n, side) <= kSameSurfaceCos) return false;
    // In sight of the point, lifted off both surfaces as a photon there would be.
    Ray along;
    along.origin = from;
    along.dir = lifted(under.position, n, x, side, lift) - from;
    along.tMax = 1.0f - kShadowEpsilon;
    return !m_accel->occluded(along);
  };
  DiscCover out;
  Vec2 at;
  int covered = 0;
  for (int i = 0; i < kAreaProbes; ++i) covered += probe(i, kAreaProbes, at) ? 1 : 0;
  out.fraction = float(std::max(covered, 1)) / float(kAreaProbes);
  if (covered == kAreaProbes || !shape) return out;  // the whole disc is centred on x
  // Part of the disc: its shape, from more probes (uniform over the disc, so the covered ones are
  // uniform over the part): the share, the centroid and the covariance of the part.
  covered = 0;
  Vec2 sum(0.0f);
  float sxx = 0.0f, sxy = 0.0f, syy = 0.0f;
  for (int i = 0; i < kEdgeProbes; ++i)
    if (probe(i, kEdgeProbes, at)) {
      ++covered;
      sum += at;
      sxx += at.x * at.x;
      sxy += at.x * at.y;
      syy += at.y * at.y;
    }
  out.fraction = float(std::max(covered, 1)) / float(kEdgeProbes);
  if (covered < kMinGradientProbes) return out;
  const float n = float(covered);
  out.centroid = sum / n;
  out.xx = sxx / n - out.centroid.x * out.centroid.x;
  out.xy = sxy / n - out.centroid.x * out.centroid.y;
  out.yy = syy / n - out.centroid.y * out.centroid.y;
  out.part = true;
  return out;
}

Vec3 PhotonRadiance::irradianceAt(const Vec3& x, const Vec3& xError, const Vec3& side, float* radius,
                                   int skipStride, const Lobe* lobe) const {
  thread_local std::vector<KdNeighbor> neighbors;
  const float maxDist2 = m_settings.maxRadius * m_settings.maxRadius;
  const int k = m_settings.k;
  if (radius) *radius = 0.0f;
  // The photons that estimate: all, or (skipStride > 1) those whose index is not a multiple of
  // it, the k nearest of them found by asking for enough more than k.
  const auto counts = [skipStride](uint32_t index) {
    return skipStride <= 1 || index % uint32_t(skipStride) != 0;
  };
  int asked = skipStride > 1 ? k + k / (skipStride - 1) + 4 : k;
  size_t found = 0, usable = 0;
  for (;;) {
    found = m_tree.knn(x, asked, maxDist2, neighbors);
    usable = 0;
    size_t last = 0;
    for (size_t i = 0; i < found && usable < size_t(k); ++i)
      if (counts(neighbors[i].index)) ++usable, last = i;
    if (usable == size_t(k) || found < size_t(asked)) {
      neighbors.resize(usable == size_t(k) ? last + 1 : found);
      break;
    }
    asked *= 2;
  }
  if (usable == 0) return Vec3(0.0f);
  // The disc: out to the k-th photon, or the largest radius where fewer lie inside it.
  const float r2 = usable == size_t(k) ? neighbors.back().dist2 : maxDist2;
  if (!(r2 > 0.0f)) return Vec3(0.0f);
  const float r = std::sqrt(r2);
  if (radius) *radius = r;
  const float lift = kLift * r;
  const Vec3 from = x + side * (lift + glm::dot(glm::abs(side), xError));
  const Frame planeFrame(side);  // the disc's plane, as cover() lays its probes in it (edgeFit)
  // With k found, the k-th photon only marks the radius: (k - 1) / (pi r_k^2) is the unbiased
  // density of a uniform process, k / (pi r_k^2) is k / (k - 1) too high (Jensen's estimate
  // counts it; at k = 32 the hall came out 3% brighter).
  const size_t counted = usable == size_t(k) && k > 1 ? neighbors.size() - 1 : neighbors.size();
  thread_local std::vector<std::pair<Vec2, Vec3>> used;  // in the disc's plane, the flux
  used.clear();
  Vec3 sum(0.0f);
  for (size_t i = 0; i < counted; ++i) {
    if (!counts(neighbors[i].index)) continue;
    const Photon& ph = m_photons[neighbors[i].index];
    if (glm::dot(ph.normal, side) <= kSameSurfaceCos) continue;
    if (std::abs(glm::dot(ph.position - x, side)) > kPlaneSlab * r) continue;
    // In sight: nothing between the point and the photon, both lifted off their surfaces.
    Ray ray;
    ray.origin = from;
    ray.dir = lifted(ph.position, ph.normal, x, side, lift) - from;
    ray.tMax = 1.0f - kShadowEpsilon;
    if (m_accel->occluded(ray)) continue;
    const Vec3 flux =
        lobe ? bsdfEval(*lobe->material, lobe->wo, lobe->frame.toLocal(ph.incident)) * ph.power : ph.power;
    sum += flux;
    if (m_settings.edgeFit)
      used.emplace_back(Vec2(glm::dot(ph.position - x, planeFrame.s), glm::dot(ph.position - x, planeFrame.t)), flux);
  }
  // Left-out photons carry their share of the flux: the rest stand for all of it.
  if (skipStride > 1) sum *= float(skipStride) / float(skipStride - 1);
  if (isBlack(sum)) return sum;
  // Jensen eq. 7.6 before the BSDF, E = sum Phi / (pi r^2), over the part of the disc that is
  // this surface in sight of the point: at a corner or an edge half the disc is not (a wall, a
  // drop), and the plain estimate came out up to half as bright there.
  const DiscCover part = cover(x, side, from, r, lift, m_settings.edgeFit);
  const float area = kPi * r2 * part.fraction;
  if (!part.part) return sum / area;
  // A part of the disc (an edge, a corner) is not centred on x: the plain estimate is the light
  // at the part's centroid c, and where the light changes across the part (a wall's top beside
  // the ceiling, lit less than lower down) that is not x's. A linear fit over the part (local
  // linear density estimation): E(p) = E(c) + g.(p - c), with sum Phi_i (p_i - c) = A S g (S the
  // part's covariance) gives E(x) = sum Phi_i (1 - c^T S^-1 (p_i - c)) / A. Regularized where the
  // part is a thin strip; the fit's change kept within kMaxEdgeChange of the plain estimate.
  const float reg = kCovarianceFloor * r2;
  const float a = part.xx + reg, b = part.xy, d = part.yy + reg;
  const float det = a * d - b * b;
  if (!(det > 0.0f)) return sum / area;
  // q = S^-1 c: the weight of photon i is 1 - q.(p_i - c).
  const Vec2 q((d * part.centroid.x - b * part.centroid.y) / det, (a * part.centroid.y - b * part.centroid.x) / det);
  Vec3 fit(0.0f);
  for (const auto& [at, flux] : used) fit += flux * (1.0f - glm::dot(q, at - part.centroid));
  if (skipStride > 1) fit *= float(skipStride) / float(skipStride - 1);
  fit = glm::clamp(fit, sum / kMaxEdgeChange, sum * kMaxEdgeChange);
  return fit / area;
}

bool PhotonRadiance::cachedIrradiance(const Vec3& x, const Vec3& xError, const Vec3& side, Vec3& out) const {
  if (m_cache.empty()) return false;
  thread_local std::vector<KdNeighbor> near;
  const float maxDist2 = m_settings.maxRadius * m_settings.maxRadius;
  m_cacheTree.knn(x, kCacheCandidates, maxDist2, near);
  // The nearest entry that passes the filters (on x's side and tangent plane, nothing standing
  // between). (Asking also that the entry's own disc reach x kept the entries of large discs,
  // low estimates: -13% at k = 8.)
  for (const KdNeighbor& n : near) {
    const CacheEntry& c = m_cache[n.index];
    if (glm::dot(c.normal, side) <= kSameSurfaceCos) continue;
    const CacheEstimate est = estimate(n.index);
    if (!(est.radius > 0.0f)) continue;
    if (std::abs(glm::dot(c.position - x, side)) > kPlaneSlab * est.radius) continue;
    const float lift = kLift * est.radius;
    const Vec3 from = x + side * (lift + glm::dot(glm::abs(side), xError));
    Ray ray;
    ray.origin = from;
    ray.dir = lifted(c.position, c.normal, x, side, lift) - from;
    ray.tMax = 1.0f - kShadowEpsilon;
    if (m_accel->occluded(ray)) continue;
    out = est.irradiance;
    return true;
  }
  return false;
}

Vec3 PhotonRadiance::reflected(const SurfaceHit& hit, const Vec3& side, const Vec3& woWorld) const {
  if (m_photons.empty()) return Vec3(0.0f);
  Material textured;
  const Frame frame(hit.shadingNormal);
  const Lobe lobe{&m_scene->materialAt(hit, textured), frame, frame.toLocal(woWorld)};
  return irradianceAt(hit.position, hit.positionError, side, nullptr, 0, &lobe);
}

Vec3 PhotonRadiance::radiance(const SurfaceHit& hit, const Vec3& side) const {
  if (m_photons.empty()) return Vec3(0.0f);
  Material textured;
  const Material& mat = m_scene->materialAt(hit, textured);
  if (!mat.hasDiffuseBase()) return Vec3(0.0f);
  // Diffuse reflection of the irradiance: albedo / pi (Oren-Nayar taken as Lambertian here, a
  // coated base by its reflectance through the coat, diffuseReflectance).
  return diffuseReflectance(mat) * kInvPi * irradiance(hit, side);
}

Vec3 PhotonRadiance::irradiance(const SurfaceHit& hit, const Vec3& side) const {
  if (m_photons.empty()) return Vec3(0.0f);
  Vec3 e;
  if (!cachedIrradiance(hit.position, hit.positionError, side, e)) e = irradianceAt(hit.position, hit.positionError, side);
  return e;
}

}  // namespace voxcone

// The voxcone method: exact specular chains and direct light, cone-gathered indirect light.

#include "voxcone/integrator/voxel_cone.h"

#include "delta_chain.h"
#include "options.h"
#include "voxcone/accel/accel.h"
#include "voxcone/core/error.h"
#include "voxcone/core/timer.h"
#include "voxcone/integrator/indirect_filter.h"
#include "voxcone/integrator/whitted.h"
#include "voxcone/scene/bsdf.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace voxcone {

namespace {
/// A trilinear lookup reaches 1 voxel from its centre, and a surface fills voxels whose centres
/// lie within half a voxel diagonal of it: a lookup of voxel size v at height h above a plane
/// does not see the plane when v <= h / kClearance.
constexpr float kClearance = 1.0f + 0.8660254f;
/// A cone stops when 99% of it is covered: the rest can add at most 1% of its radiance.
constexpr float kOpaque = 0.99f;
/// Defaults chosen by time to error against path at 4096 spp (cornell-box, cornell-dragon and
/// cornell-dragon-glass, 256x256, 2 threads; the README's "Where voxcone's time goes" has the
/// figures): level 6 (level 5 is faster on cornell-box but loses 0.9 dB on the dragon, level 7
/// costs 1.5x for +0.2 dB). Indirect light: one gathering pixel per 4x4 block, one gather there
/// (its first sample), the filter of radius 12 filling the rest. Cornell-box at 4 spp (total s,
/// dB): spacing 3 / 4 / 5 with filter 12 and 1 gather 0.21 / 0.17 / 0.17 s, 36.13 / 35.86 /
/// 35.45 dB (2 gathers: +0.4-0.6 dB for +0.02-0.03 s); filter 8 / 10 / 12 at spacing 4: 35.22 /
/// 35.64 / 35.86 dB in the same time; 3 spp 33.45 dB (direct light needs 4 stratified samples:
/// 25.4 / 29.6 / 35.5 / 42.5 dB at 1 / 2 / 4 / 8 spp of it alone).
constexpr int kDefaultLevel = 6;
constexpr int kDefaultGathers = 1;
constexpr int kDefaultFilterRadius = 12;
constexpr int kDefaultGatherSpacing = 4;
/// Names of VoxelConeIntegrator::View, in order.
const std::vector<std::string> kViewNames = {"full", "direct", "indirect", "caustic", "field"};
}  // namespace

VoxelConeIntegrator::VoxelConeIntegrator(const IntegratorContext& c)
    : m_scene(c.scene), m_accel(c.accel), m_maxDepth(c.settings.maxDepth) {
  OptionReader r(c.options, "voxcone");
  constexpr int kMaxInt = std::numeric_limits<int>::max();
  bool anyDelta = false;
  for (const Material& m : m_scene.materials) anyDelta = anyDelta || m.isDelta();

  m_voxelSettings.level = r.integer("level", kDefaultLevel, 1, 12);
  m_voxelSettings.coarsestLevel = r.integer("coarsest_level", std::min(1, m_voxelSettings.level), 0,
                                            m_voxelSettings.level);
  m_voxelSettings.causticLevel = r.integer("caustic_level", anyDelta ? std::min(12, m_voxelSettings.level + 1) : 0,
                                           0, 12);
  if (m_voxelSettings.causticLevel != 0 && m_voxelSettings.causticLevel < m_voxelSettings.coarsestLevel)
    throw SettingsError("voxcone.caustic_level: must be 0 or at least coarsest_level");
  m_voxelSettings.kernelSigmaVoxels = float(r.number("kernel_sigma", 0.75, 0.05, 16.0));
  uint64_t photons, causticPhotons;
  defaultPhotonCounts(c.settings.photons, c.settings.causticPhotons, kVoxconeDefaultPhotons,
                      kVoxconeDefaultCausticPhotons, photons, causticPhotons);
  m_photonSettings.photons = uint64_t(r.integer("photons", int(std::min<uint64_t>(photons, kMaxInt)), 0, kMaxInt));
  m_photonSettings.causticPhotons =
      uint64_t(r.integer("caustic_photons", int(std::min<uint64_t>(causticPhotons, kMaxInt)), 0, kMaxInt));
  m_photonSettings.seed = c.settings.seed + uint64_t(r.integer("seed", 0, 0, kMaxInt));
  m_photonSettings.maxDepth = std::max(1, m_maxDepth);
  if (!anyDelta || m_voxelSettings.causticLevel == 0) m_photonSettings.causticPhotons = 0;

  const int cones = r.integer("cones", 6, 1, 256);
  const double angleDeg = r.number("cone_angle", 0.0, 0.0, 89.0);
  m_cones = ConeSet(cones, float(angleDeg * kPi / 180.0));
  m_tanHalf = std::tan(m_cones.halfAngle());
  m_coneStep = float(r.number("cone_step", 1.0, 0.25, 4.0));
  const float sceneRadius = std::max(0.0f, m_scene.boundingSphere().radius);
  m_maxDistance = float(r.number("max_distance", 2.0 * double(sceneRadius), 0.0, 1e30));
  m_lightSamples = r.integer("light_samples", 1, 1, 1024);
  m_gathers = r.integer("gathers", kDefaultGathers, 0, 1 << 24);
  m_filterRadius = r.integer("filter", kDefaultFilterRadius, 0, 64);
  m_gatherSpacing = r.integer("gather_spacing", m_filterRadius > 0 ? kDefaultGatherSpacing : 1, 1, 16);
  if (m_gatherSpacing > 1 && m_filterRadius == 0)
    throw SettingsError("voxcone.gather_spacing: above 1 needs the filter (filter > 0) to fill the other pixels");
  m_exactSegment = float(r.number("exact_segment", 32.0, 0.0, 1e6));
  m_hitGather = r.choice("gather", {"march", "hit"}) == "hit";
  const std::string view = r.choice("view", kViewNames);
  m_view = View(std::find(kViewNames.begin(), kViewNames.end(), view) - kViewNames.begin());
  r.finish();
}

nlohmann::json VoxelConeIntegrator::settingsJson() const {
  return {{"max_depth", m_maxDepth},
          {"level", m_voxelSettings.level},
          {"coarsest_level", m_voxelSettings.coarsestLevel},
          {"caustic_level", m_voxelSettings.causticLevel},
          {"kernel_sigma", m_voxelSettings.kernelSigmaVoxels},
          {"photons", m_photonSettings.photons},
          {"caustic_photons", m_photonSettings.causticPhotons},
          {"photon_seed", m_photonSettings.seed},
          {"cones", m_cones.cones().size()},
          {"cone_angle", m_cones.halfAngle() * 180.0f / kPi},
          {"cone_step", m_coneStep},
          {"max_distance", m_maxDistance},
          {"light_samples", m_lightSamples},
          {"gathers", m_gathers},
          {"filter", m_filterRadius},
          {"gather_spacing", m_gatherSpacing},
          {"exact_segment", m_exactSegment},
          {"gather", m_hitGather ? "hit" : "march"},
          {"view", kViewNames[size_t(m_view)]}};
}

nlohmann::json VoxelConeIntegrator::statsJson() const {
  nlohmann::json j = m_stats;
  j["field_bytes"] = m_field.memoryBytes();
  for (int level : m_field.levels()) j["active_voxels"][std::to_string(level)] = m_field.activeVoxels(level);
  return j;
}

void VoxelConeIntegrator::setField(VoxelField field) {
  m_field = std::move(field);
  const std::vector<int> levels = m_field.levels();
  if (levels.empty()) throw SettingsError("voxcone: the voxel field has no levels");
  m_finest = levels.front();
  m_coarsest = levels.back();
  m_v0 = float(m_field.voxelSize(m_finest));
  const int causticLevel = m_field.settings().causticLevel;
  m_causticVoxel = causticLevel > 0 ? float(m_field.voxelSize(causticLevel)) : m_v0;
  m_fieldBounds = m_field.bounds();
  m_prepared = true;
}

void VoxelConeIntegrator::prepare(Progress* progress) {
  Timer total;
  const PhotonMaps maps = tracePhotons(m_scene, m_accel, m_photonSettings, progress);
  m_stats = maps.stats.toJson();
  m_stats["photon_trace_seconds"] = maps.stats.seconds;
  Timer t;
  VoxelField field = VoxelField::voxelize(m_scene, m_voxelSettings, progress, &maps.caustic);
  m_stats["voxelize_seconds"] = t.seconds();
  t.reset();
  field.inject(maps, progress);
  m_stats["inject_seconds"] = t.seconds();
  t.reset();
  field.buildMips(progress);
  m_stats["mips_seconds"] = t.seconds();
  m_stats["prepare_seconds"] = total.seconds();
  setField(std::move(field));
}

std::optional<VoxelConeIntegrator::AxisHit> VoxelConeIntegrator::hitAlongAxis(const Vec3& p, const Vec3& pError,
                                                                             const Vec3& n, const Vec3& d,
                                                                             float tMax) const {
  Ray ray = spawnRay(p, pError, n, d);
  ray.tMax = tMax;
  const std::optional<Hit> hit = m_accel.intersect(ray);
  if (!hit) return std::nullopt;
  AxisHit out;
  out.t = hit->t;
  const SurfaceHit sh = m_scene.surfaceAt(hit->triangle, hit->b1, hit->b2);
  out.position = sh.position;
  out.side = glm::dot(sh.geomNormal, d) < 0.0f ? sh.geomNormal : -sh.geomNormal;
  return out;
}

Vec3 VoxelConeIntegrator::traceCone(const Vec3& p, const Vec3& pError, const Vec3& n, const Vec3& d,
                                    float tanHalf) const {
  const float cosPhi = glm::dot(n, d);
  if (!(cosPhi > 0.0f)) return Vec3(0.0f);  // below the tangent plane: nothing to gather
  const float vMax = float(m_field.voxelSize(m_coarsest));
  // The point the lookups' voxels are seen from (each shows the side of its surface facing
  // it): the apex lifted clear of its own surface's finest voxels, whose centres lie up to
  // sqrt(3)/2 v0 off the surface and would otherwise face it from either side at random.
  const Vec3 apex = p + n * (kClearance * m_v0);
  float A = 0.0f;
  Vec3 C(0.0f);
  float tEnd = m_maxDistance;
  bool hitSurface = false;
  Vec3 hitRadiance(0.0f);
  if (m_hitGather) {
    // One exact ray along the axis; the radiance at its hit, filtered over the cone's width there.
    const std::optional<AxisHit> hit = hitAlongAxis(p, pError, n, d, m_maxDistance);
    if (!hit) return Vec3(0.0f);
    const float v = std::clamp(hit->t * tanHalf, m_v0, vMax);
    return m_field.coneSample(hit->position + hit->side * (0.5f * v), float(m_finest) - std::log2(v / m_v0), d, apex)
        .radiance;
  }
  // Exact visibility along the axis for the first segment (leak mitigation).
  if (m_exactSegment > 0.0f) {
    if (const std::optional<AxisHit> hit = hitAlongAxis(p, pError, n, d, m_exactSegment * m_v0)) {
      hitSurface = true;
      // The finest level around the hit, half a voxel towards the ray's side.
      hitRadiance = m_field.coneSample(hit->position + hit->side * (0.5f * m_v0), float(m_finest), d, apex).radiance;
      // March only the part of the cone before the surface: lookups whose reach (kClearance v)
      // stays in front of it.
      tEnd = std::min(tEnd, hit->t);
    }
  }
  // The march follows the cone's own axis from p. Its first lookup is where a finest-level
  // lookup clears the surface (height kClearance v0 above the tangent plane); the axis before
  // it is covered by the exact segment. (Starting from p + kClearance v0 n instead shifts the
  // whole cone towards what it looks at: an occluder 8 voxels above the surface then looks a
  // fifth closer, and its indirect light came out 30% too bright at level 6.)
  float t = kClearance * m_v0 / cosPhi;
  while (t < tEnd && A < kOpaque) {
    // The lookup size: the cone's width, but clear of the own surface. A fractional level
    // blends in the next coarser mip, whose voxels must clear the surface too: where they
    // would not, the lookup takes the finest whole level that does.
    const float vClear = t * cosPhi / kClearance;
    float v = std::min(t * tanHalf, vClear);
    if (v > m_v0 && m_v0 * ceilPow2(v / m_v0) > vClear) v = m_v0 * floorPow2(vClear / m_v0);
    v = std::clamp(v, m_v0, vMax);
    if (hitSurface && t + kClearance * v > tEnd) break;
    const Vec3 x = p + d * t;
    // Outside the field by more than a lookup's reach: nothing more to gather. Voxel centres lie
    // half a voxel inside the field and a trilinear lookup reaches one voxel from them; the
    // coarser of the two blended mips has voxels up to 2 v: 1.5 * 2 v.
    const Vec3 reach(3.0f * v);
    if (!Bounds3(m_fieldBounds.lo - reach, m_fieldBounds.hi + reach).contains(x)) break;
    const float level = float(m_finest) - std::log2(v / m_v0);
    const ConeSample s = m_field.coneSample(x, level, d, apex);
    const float step = m_coneStep * v;
    // Surfaces met over this step (ConeSample::density): a plane adds up to exactly one
    // crossing over the samples near it (the trilinear tents sum to one), which makes the
    // cone opaque. Occlusion accumulates linearly: the share of the cone's cross-section the
    // step's surfaces cover, up to what is still open.
    const float crossings = s.density * step / m_v0;
    if (crossings > 0.0f) {
      const float a = std::min(1.0f - A, crossings);
      C += a * s.radiance;
      A += a;
    }
    t += step;
  }
  // The exact hit covers what the march left open.
  if (hitSurface && A < 1.0f) C += (1.0f - A) * hitRadiance;
  return C;
}

Vec3 VoxelConeIntegrator::gatherDiffuse(const SurfaceHit& sh, const Vec3& woWorld, float u) const {
  const Material& mat = m_scene.materials[sh.material];
  const Vec3 ng = glm::dot(sh.geomNormal, woWorld) >= 0.0f ? sh.geomNormal : -sh.geomNormal;
  const Frame frame(sh.shadingNormal);
  const Vec3 wo = frame.toLocal(woWorld);
  // The cone set turned by the angle 2 pi u about the normal; each cone weighted by
  // f(wo, axis) * pi * w_i, which is albedo * w_i for a Lambertian surface.
  const float rotation = 2.0f * kPi * u;
  const float cr = std::cos(rotation), sr = std::sin(rotation);
  const Frame geo(ng);
  Vec3 indirect(0.0f);
  for (const Cone& cone : m_cones.cones()) {
    const Vec3 d =
        geo.toWorld(Vec3(cr * cone.axis.x - sr * cone.axis.y, sr * cone.axis.x + cr * cone.axis.y, cone.axis.z));
    const Vec3 f = mat.type == MaterialType::Lambertian ? mat.albedo : kPi * bsdfEval(mat, wo, frame.toLocal(d));
    if (isBlack(f)) continue;
    indirect += cone.weight * f * traceCone(sh.position, sh.positionError, ng, d, m_tanHalf);
  }
  return indirect;
}

Vec3 VoxelConeIntegrator::gatherDeferred(const DeferredGather& g) const { return gatherDiffuse(g.hit, g.wo, g.u); }

Vec3 VoxelConeIntegrator::shade(const SurfaceHit& sh, const Vec3& woWorld, Sampler& sampler,
                                 IndirectSplit* split) const {
  const Material& mat = m_scene.materials[sh.material];
  // A viewpoint on the viewer's side, clear of the surface's own voxels of size `voxel` (as the
  // cones' apex in traceCone).
  const auto viewFrom = [&](const Vec3& dir, float voxel) { return sh.position + dir * (kClearance * voxel); };
  if (m_view == View::Field)
    return m_field.coneSample(sh.position, float(m_finest), -woWorld, viewFrom(woWorld, m_v0)).radiance;
  Vec3 L(0.0f);
  if (m_view == View::Full || m_view == View::Direct)
    L += estimateDirectLight(m_scene, m_accel, sh, woWorld, sampler, m_lightSamples);
  if (m_view == View::Direct) return L;
  // Cones on the pixel's first `gathers` samples only, weighted to keep the pixel's mean.
  float gatherWeight = 1.0f;
  if (m_gathers > 0 && sampler.samplesPerPixel() > uint32_t(m_gathers))
    gatherWeight = sampler.sampleIndex() < uint32_t(m_gathers) ? float(sampler.samplesPerPixel()) / float(m_gathers)
                                                               : 0.0f;
  // The side of the surface the viewer is on.
  const bool front = glm::dot(sh.geomNormal, woWorld) >= 0.0f;
  const Vec3 ng = front ? sh.geomNormal : -sh.geomNormal;
  const Frame frame(sh.shadingNormal);
  const Vec3 wo = frame.toLocal(woWorld);
  if (mat.isDiffuse()) {
    if (m_view != View::Indirect) L += m_field.causticRadiance(sh.position, viewFrom(ng, m_causticVoxel));
    if (m_view == View::Caustic) return L;
    if (split) {
      split->valid = true;
      split->position = sh.position;
      split->normal = ng;
      split->material = sh.material;
    }
    if (gatherWeight == 0.0f) return L;
    const float u = sampler.uniform();
    // With the filter the cones wait until renderImage knows whether this pixel needs them.
    if (split) {
      split->deferred = true;
      split->gather = {sh, woWorld, u, gatherWeight};
      return L;
    }
    return L + gatherWeight * gatherDiffuse(sh, woWorld, u);
  }
  if (m_view == View::Caustic || gatherWeight == 0.0f) return L;
  // Glossy: one cone along a BSDF-sampled direction, as wide as the roughness.
  BsdfSample bs;
  if (!bsdfSampleFrom(mat, wo, sampler, bs)) return L;
  const Vec3 d = frame.toWorld(bs.wi);
  const Vec3 side = glm::dot(d, sh.geomNormal) >= 0.0f ? sh.geomNormal : -sh.geomNormal;
  // Roughness is in (0, 1]. Below 0.01 the cone would stay one finest voxel wide for over 100
  // steps; the lookups cannot resolve less than a voxel anyway.
  const float tanHalf = std::max(mat.roughness, 0.01f);
  L += gatherWeight * bs.weight * traceCone(sh.position, sh.positionError, side, d, tanHalf);
  return L;
}

Vec3 VoxelConeIntegrator::trace(const Ray& ray, Sampler& sampler, IndirectSplit* split) const {
  if (!m_prepared) throw Error("voxcone: li() before prepare()");
  // Emission is seen directly or through delta bounces (shadow rays sample it elsewhere).
  const bool emission = m_view == View::Full || m_view == View::Direct;
  // Only the camera ray's own first hit is split off for the screen-space filter.
  return traceDeltaChains(m_scene, m_accel, ray, sampler, m_maxDepth, emission,
                          [this, split](const SurfaceHit& sh, const Vec3& wo, Sampler& px, int depth) {
                            return shade(sh, wo, px, depth == 0 ? split : nullptr);
                          });
}

Vec3 VoxelConeIntegrator::li(const Ray& ray, Sampler& sampler) const { return trace(ray, sampler, nullptr); }

void VoxelConeIntegrator::linkIndirect(IndirectBuffer& b) const {
  b.link.assign(b.indirect.size(), 0u);
  tbb::parallel_for(0, b.height, [&](int y) {
    for (int x = 0; x < b.width; ++x) {
      const size_t p = size_t(y) * size_t(b.width) + size_t(x);
      if (!b.filterable[p]) continue;
      // Bit 0: the right neighbour, bit 1: the one below.
      const bool has[2] = {x + 1 < b.width, y + 1 < b.height};
      const size_t q[2] = {p + 1, p + size_t(b.width)};
      for (int bit = 0; bit < 2; ++bit) {
        if (!has[bit] || !sameFilterSurface(b, p, q[bit])) continue;
        // Both ends a quarter of the pixel's footprint above the surface: an occluder between
        // the two points (a wall seen edge-on) cuts the link, the surface itself cannot.
        const Vec3 from = b.position[p] + b.normal[p] * (0.25f * b.footprint[p]);
        const Vec3 to = b.position[q[bit]] + b.normal[q[bit]] * (0.25f * b.footprint[p]);
        if (linkedPoints(from, to)) b.link[p] |= uint8_t(1u << bit);
      }
    }
  });
}

bool VoxelConeIntegrator::linkedPoints(const Vec3& from, const Vec3& to) const {
  Ray r;
  r.origin = from;
  r.dir = to - from;
  r.tMax = 1.0f;
  return !m_accel.occluded(r);
}

Vec3 VoxelConeIntegrator::liSplit(const Ray& ray, Sampler& sampler, IndirectSplit& split) const {
  split = IndirectSplit();
  return trace(ray, sampler, &split);
}

}  // namespace voxcone

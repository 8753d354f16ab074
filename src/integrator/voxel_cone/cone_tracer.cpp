// One cone through the voxel field: the march, the exact segment and gather = "hit".

#include "voxcone/integrator/voxel_cone/cone_tracer.h"

#include "voxcone/accel/accel.h"
#include "voxcone/core/error.h"
#include "voxcone/core/rng.h"
#include "voxcone/integrator/direct_light.h"
#include "voxcone/integrator/voxel_cone/settings.h"
#include "voxcone/photon/light_proximity.h"
#include "voxcone/photon/photon_radiance.h"
#include "voxcone/scene/bsdf.h"
#include "voxcone/scene/scene.h"
#include "voxcone/voxel/voxel_field.h"

#include <algorithm>
#include <cmath>
#include <cstring>

namespace voxcone {

namespace {
/// Whether the lights a hit's shadow rays sample (all but the environment) are one point light or
/// one sun without extent: every sample is then the same ray.
bool onlyOneDeltaLight(const Scene& scene) {
  if (scene.emissiveTriangleCount() > 0 || scene.pointLights.size() + scene.directionalLights.size() != 1) return false;
  return scene.pointLights.size() == 1 || scene.directionalLights[0].isDelta();
}
}  // namespace

ConeTracer::ConeTracer(const Scene& scene, const Accel& accel, const VoxelField& field, const VoxelConeSettings& s,
                       const PhotonRadiance* photons, const LightProximity* proximity)
    : m_scene(scene), m_accel(accel), m_field(field), m_photons(s.hitPhotons ? photons : nullptr),
      m_proximity(m_photons && proximity && !proximity->empty() ? proximity : nullptr),
      m_coneStep(s.coneStep), m_maxDistance(s.maxDistance), m_exactSegment(s.exactSegment),
      m_hitGather(s.hitGather), m_hitDirect(s.hitPhotons && s.hitDirect),
      m_hitLightSamples(onlyOneDeltaLight(scene) ? 1 : std::max(s.hitLightSamples, 1)),
      m_hitEnvironment(m_hitDirect && scene.environment) {
  const std::vector<int> levels = m_field.levels();
  if (levels.empty()) throw SettingsError("voxcone: the voxel field has no levels");
  m_finest = levels.front();
  m_coarsest = levels.back();
  m_v0 = float(m_field.voxelSize(m_finest));
  m_fieldBounds = m_field.bounds();
  m_footprint = LookupFootprint::of(m_field.settings().mipFilter);
}

float ConeTracer::crossSectionVariance(float tanHalf) {
  // Directions uniform over the cap of half-angle theta (c = cos theta) meet the plane at unit
  // distance along the axis at tan(alpha) from it: E[tan^2 alpha] = integral of tan^2 alpha
  // sin alpha over [0, theta] / (1 - c) = ((1 - c)^2 / c) / (1 - c) = (1 - c) / c, half of it
  // per axis; the mean is the axis. (tan^2 theta / 4 for narrow cones: the uniform disk's.)
  const float c = 1.0f / std::sqrt(1.0f + tanHalf * tanHalf);
  // 1 - c without cancellation: 1 - c = tan^2 c^2 / (1 + c).
  const float oneMinusC = tanHalf * tanHalf * c * c / (1.0f + c);
  return 0.5f * oneMinusC / c;
}

std::optional<ConeTracer::AxisHit> ConeTracer::hitAlongAxis(const Vec3& p, const Vec3& pError, const Vec3& n,
                                                            const Vec3& d, float tMax) const {
  Ray ray = spawnRay(p, pError, n, d);
  ray.tMax = tMax;
  const std::optional<Hit> hit = m_accel.intersect(ray);
  if (!hit) return std::nullopt;
  AxisHit out;
  out.t = hit->t;
  const SurfaceHit sh = m_scene.surfaceAt(hit->triangle, hit->b1, hit->b2);
  out.side = glm::dot(sh.geomNormal, d) < 0.0f ? sh.geomNormal : -sh.geomNormal;
  out.surface = sh;
  return out;
}

namespace {
/// The nearest a light counts as to a cone's hit, in lookup sizes (hitRadiance).
constexpr float kHitLightClamp = 0.25f;
/// The R2 sequence's steps: 1 / g and 1 / g^2 for the plastic number g.
constexpr Vec2 kR2(0.7548776662f, 0.5698402910f);
}  // namespace

Vec3 ConeTracer::hitRadiance(const AxisHit& hit, const Vec3& d, const Vec3& apex, float v, const Vec2& lightU,
                             bool nearSplit) const {
  if (m_photons) {
    // Beside a lamp the cone takes its share of the hit's light, the photons that left it the rest
    // (LightProximity); its lamps then need no clamp: within the radius the share falls as d^2.
    const bool split = nearSplit && m_proximity;
    const float share = split ? m_proximity->coneShare(hit.surface.position) : 1.0f;
    if (!(share > 0.0f)) return Vec3(0.0f);
    const float clamp = split ? 0.0f : kHitLightClamp * v;
    Vec3 L = m_photons->radiance(hit.surface, hit.side);
    if (m_hitDirect && m_scene.materials[hit.surface.material].hasDiffuseBase()) {
      // The lamps and suns by one sample, the sky by another: chosen together by power, a sky
      // seen through a window took most samples and left each lamp's few a large weight
      // (tools/make_gltf_room.py's room with its lamp 0.4 m under the ceiling: a bright blotch
      // wherever a cone's hit drew the lamp, 32x32 blocks up to 2.2x path; 0.92-1.10 after).
      // Without near_light a lamp nearer the hit than kHitLightClamp v counts as that far: the
      // hit stands for the cone's footprint, and a light point a millimetre away gave one sample
      // a weight of thousands (the room with its lamp 2 cm under the ceiling: blocks up to 2.6x
      // Cycles at some seeds; clamped at 0.25 v, within 0.85-1.18 at four seeds and the image 1%
      // darker, at 0.5 v 2% darker).
      // Several shadow rays, their samples the R2 sequence's (Roberts 2018) around the cone's.
      Vec3 direct(0.0f);
      for (int j = 0; j < m_hitLightSamples; ++j) {
        const Vec2 u(std::fmod(lightU.x + kR2.x * float(j), 1.0f), std::fmod(lightU.y + kR2.y * float(j), 1.0f));
        direct += directLightSample(m_scene, m_accel, hit.surface, -d, u, false, clamp);
      }
      L += direct / float(m_hitLightSamples);
      // The sky by its photons where the estimate keeps them (hit_sky: photons); elsewhere, and
      // with hit_sky: rays, by a shadow ray. (Outside the region, the ground seen through a window
      // from beside it where few gathers read, the ray is what is left: without it a ceiling
      // above a window came out 10% dark, tools/make_gltf_room.py --held-out-2.)
      if (m_hitEnvironment && !m_photons->settings().keepsSky(hit.surface.position, hit.side)) {
        // The sky's pair: the lamps' shifted by irrational steps (a Cranley-Patterson rotation),
        // so the two samples of one hit do not share their point.
        const Vec2 skyU(std::fmod(lightU.x + 0.61803399f, 1.0f), std::fmod(lightU.y + 0.41421356f, 1.0f));
        L += environmentLightSample(m_scene, m_accel, hit.surface, -d, skyU);
      }
    }
    return share * L;
  }
  return m_field.coneSample(hit.surface.position + hit.side * (0.5f * v), float(m_finest) - std::log2(v / m_v0), d, apex)
      .radiance;
}

Vec3 ConeTracer::continueSpecular(const SurfaceHit& sh, const Vec3& d, float tanHalf, const Vec2& lightU,
                                  int depth, Vec3* deltaLight, bool nearSplit) const {
  if (depth + 1 > kMaxSpecularDepth) return Vec3(0.0f);
  Material textured;
  const Material& m = m_scene.materialAt(sh, textured);
  const Frame frame(sh.shadingNormal);
  DeltaLobe lobes[2];
  const int count = bsdfDeltaLobes(m, frame.toLocal(-d), lobes);
  Vec3 L(0.0f);
  for (int i = 0; i < count; ++i) {
    if (maxComponent(lobes[i].weight) < kSpecularCut) continue;
    const Vec3 wi = frame.toWorld(lobes[i].wi);
    const Vec3 side = glm::dot(sh.geomNormal, wi) > 0.0f ? sh.geomNormal : -sh.geomNormal;
    Vec3 found(0.0f);
    L += lobes[i].weight * trace(sh.position, sh.positionError, side, wi, tanHalf, lightU, depth + 1, false, nullptr,
                                 deltaLight ? &found : nullptr, nearSplit);
    if (deltaLight) *deltaLight += lobes[i].weight * found;
  }
  return L;
}

Vec3 ConeTracer::continueGlossy(const SurfaceHit& sh, const Vec3& d, const Vec2& lightU, int depth,
                                bool nearSplit) const {
  if (depth + 1 > kMaxSpecularDepth) return Vec3(0.0f);
  Material textured;
  const Material& m = m_scene.materialAt(sh, textured);
  Vec3 L = directLightSample(m_scene, m_accel, sh, -d, lightU);
  // The cone's lightU is its only random pair (a Hammersley point, shifted per gather): the
  // direction's numbers and the next hit's light sample are a hash of its bits, independent of
  // the light sample taken here.
  uint32_t bits[2];
  std::memcpy(bits, &lightU, sizeof bits);
  const uint64_t k0 = mixBits((uint64_t(bits[0]) << 32 | bits[1]) + 0x9e3779b97f4a7c15ULL), k1 = mixBits(k0);
  const auto unit = [](uint64_t k, int shift) { return float((k >> shift) & 0xffffffu) * 0x1p-24f; };
  const float uc = unit(k0, 40);
  const Vec2 u(unit(k0, 16), unit(k1, 40)), nextLightU(unit(k1, 16), unit(mixBits(k1), 40));
  const Frame frame(sh.shadingNormal);
  BsdfSample bs;
  if (!bsdfSample(m, frame.toLocal(-d), uc, u, bs) || isBlack(bs.weight)) return L;
  const Vec3 wi = frame.toWorld(bs.wi);
  const Vec3 side = glm::dot(sh.geomNormal, wi) > 0.0f ? sh.geomNormal : -sh.geomNormal;
  L += bs.weight * trace(sh.position, sh.positionError, side, wi, std::max(m.roughness, 0.01f), nextLightU, depth + 1,
                         false, nullptr, nullptr, nearSplit);
  return L;
}

Vec3 ConeTracer::trace(const Vec3& p, const Vec3& pError, const Vec3& n, const Vec3& d, float tanHalf,
                       const Vec2& lightU, int depth, bool sky, std::optional<SurfaceHit>* axisHit,
                       Vec3* deltaLight, bool nearSplit) const {
  const float cosPhi = glm::dot(n, d);
  if (!(cosPhi > 0.0f)) return Vec3(0.0f);  // below the tangent plane: nothing to gather
  const float vMax = float(m_field.voxelSize(m_coarsest));
  // The point the lookups' voxels are seen from (each shows the side of its surface facing
  // it): the apex lifted clear of its own surface's finest voxels, whose centres lie up to
  // sqrt(3)/2 v0 off the surface and would otherwise face it from either side at random.
  const Vec3 apex = p + n * (kApexLift * m_v0);
  // The lookup size whose footprint has the cone's cross-section variance at distance t
  // (LookupFootprint): v^2 = a sigma^2 + b v0^2, sigma^2 = t^2 crossSectionVariance.
  const float va = m_footprint.a * crossSectionVariance(tanHalf), vb = m_footprint.b * m_v0 * m_v0;
  auto lookupSize = [&](float t) { return std::sqrt(va * t * t + vb); };
  float A = 0.0f;
  Vec3 C(0.0f);
  float tEnd = m_maxDistance;
  bool hitSurface = false;
  Vec3 hitLight(0.0f);
  if (m_hitGather) {
    // One exact ray along the axis; the radiance at its hit, filtered over the cone's width there.
    const std::optional<AxisHit> hit = hitAlongAxis(p, pError, n, d, m_maxDistance);
    if (axisHit) *axisHit = hit ? std::optional<SurfaceHit>(hit->surface) : std::nullopt;
    // Past a mirror or glass (depth > 0), what a glossy cone's light samples cannot reach.
    const bool throughDelta = deltaLight && depth > 0;
    if (!hit) {
      if (throughDelta) *deltaLight += m_scene.escaped(d);
      return sky ? m_scene.escapedSky(d) : Vec3(0.0f);
    }
    const Material& hm = m_scene.materials[hit->surface.material];
    if (hm.isDelta()) return continueSpecular(hit->surface, d, tanHalf, lightU, depth, deltaLight, nearSplit);
    if (throughDelta) *deltaLight += m_scene.emitted(hit->surface, -d);
    if (m_photons && !hm.hasDiffuseBase()) return continueGlossy(hit->surface, d, lightU, depth, nearSplit);
    return hitRadiance(*hit, d, apex, std::clamp(lookupSize(hit->t), m_v0, vMax), lightU, nearSplit);
  }
  // Exact visibility along the axis for the first segment (leak mitigation).
  if (m_exactSegment > 0.0f) {
    if (const std::optional<AxisHit> hit = hitAlongAxis(p, pError, n, d, m_exactSegment * m_v0)) {
      hitSurface = true;
      // A mirror or glass passes on what its exact reflected and refracted cones gather;
      // elsewhere the finest level around the hit, half a voxel towards the ray's side.
      if (m_scene.materials[hit->surface.material].isDelta())
        hitLight = continueSpecular(hit->surface, d, tanHalf, lightU, depth, nullptr, false);
      else
        hitLight = hitRadiance(*hit, d, apex, m_v0, lightU, false);
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
    float v = std::min(lookupSize(t), vClear);
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
  if (hitSurface && A < 1.0f) C += (1.0f - A) * hitLight;
  return C;
}

}  // namespace voxcone

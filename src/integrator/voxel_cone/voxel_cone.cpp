// The voxcone method: exact specular chains and direct light, cone-gathered indirect light.

#include "voxcone/integrator/voxel_cone/voxel_cone.h"

#include "../delta_chain.h"
#include "voxcone/accel/accel.h"
#include "voxcone/core/error.h"
#include "voxcone/core/rng.h"
#include "voxcone/core/sampler.h"
#include "voxcone/core/sampling.h"
#include "voxcone/core/timer.h"
#include "voxcone/integrator/direct_light.h"
#include "voxcone/integrator/indirect_filter.h"
#include "voxcone/photon/emission_guide.h"
#include "voxcone/photon/light_proximity.h"
#include "voxcone/photon/seen_region.h"
#include "voxcone/scene/bsdf.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <optional>

namespace voxcone {

namespace {
/// The emission guide's boxes are cut while they hold this many of the pilot's useful photons
/// (EmissionGuide::fromUseful); fewer in all, and no guide is built. A cut leaves about half in
/// each box, so a leaf's density rests on some 16 photons or more: a Poisson count known within
/// 1 / sqrt(16) = 25%, as the grid guide's 8 per bin (35%) were. Not measured against others.
constexpr double kGuideSplit = 32.0;
/// A guided photon weighs at most this many times a typical useful one (EmissionGuide's bound).
/// Measured on tools/make_gltf_room.py's three rooms against Cycles (seeds 0-7, 32x32 blocks:
/// the mean over blocks of each block's standard deviation across seeds; the seeds with a block
/// beyond 10%; the photons emitted), room / --held-out / --held-out-2: unbounded, one block of
/// --held-out-2 came out 1.21 (136k photons, the pilot's yield taken as the guide's); 8: 0.0165
/// / 0.0167 / 0.0176, 2 / 2 / 0 seeds (1.30M / 1.91M / 2M photons); 16: 0.0161 / 0.0166 /
/// 0.0185, 1 / 1 / 0 (728k / 1.05M / 1.25M). The grid guide before it: 0.0148 / 0.0162 /
/// 0.0189, 0 / 1 / 2 (2M photons in each).
constexpr double kGuideMaxRatio = 16.0;
/// The useful photons a pilot is grown to where the first holds fewer: what the grid guide's
/// finest layout asked for (8 per bin in 8 x 16 x 16 bins), kept for the tree; at most an eighth
/// of max_photons (below), so it costs the sunlit hall a 179k pilot against 45k before.
constexpr double kPilotUseful = 16384.0;
/// The share of the gathers' points the distant lights' target sphere holds (SeenRegion::readSphere).
/// Measured with distant_aim 0.5 on tools/make_gltf_room.py's room against Cycles (seeds 0-7,
/// 32x32 blocks beyond 10%): 0.75 left 1 seed out (1.106), 0.9 none (worst 1.086), 1.0 two
/// (1.126); on sky-room (seeds 1-3, worst 4x4 cell) 0.75 gave up to 1.079, 0.9 1.057, 1.0 1.023.
constexpr double kDistantQuantile = 0.9;
/// near_light's default radius, per unit of the mean distance a gather's rays travel. Measured on
/// a 2 m room lit by a lamp 2 cm under its ceiling (test::lampUnderCeilingScene at 64x64, the
/// largest standard deviation of a 8x8 cell over three seeds): 0.25 / 0.5 / 1.0 gave 0.027 /
/// 0.033 / 0.048 (near_light 0: 0.149); the glTF room (tools/make_gltf_room.py) changed little
/// between 0.3 and 1.0 m (0.25 there: 0.57 m).
constexpr double kNearLightScale = 0.25;
/// A lamp pass runs where the main pass's lamp photons are fewer than lamp_photons over this.
constexpr double kNearLampStarved = 4.0;

/// Point i of an n-point Hammersley set ((i + 1/2) / n, the radical inverse of i) shifted by
/// `shift` and wrapped into [0, 1)^2 (a Cranley-Patterson rotation): the numbers of a gather's
/// cones, stratified over them, different at every gather.
Vec2 shiftedHammersley(size_t i, size_t n, const Vec2& shift) {
  Vec2 u((float(i) + 0.5f) / float(n) + shift.x, float(sobolDim0(uint32_t(i))) * 0x1p-32f + shift.y);
  u -= glm::floor(u);
  return glm::min(u, Vec2(kOneMinusEpsilon));
}
/// The pilot's photons of use (`stores`: the indices of their useful stores in maps.global, each
/// photon's next to each other, with maps.globalSamples) as the emission guide's samples, each
/// photon once with its number of useful stores.
std::vector<EmissionGuide::Useful> usefulEmissions(const PhotonMaps& maps, const std::vector<size_t>& stores) {
  std::vector<EmissionGuide::Useful> out;
  for (size_t i : stores) {
    // No two photons share a light choice (it is stratified over the pass).
    const EmissionSample& u = maps.globalSamples[i];
    if (!out.empty() && out.back().sample.uLight == u.uLight)
      out.back().stores += 1.0;
    else
      out.push_back({u, 1.0});
  }
  return out;
}
}  // namespace

VoxelConeIntegrator::VoxelConeIntegrator(const IntegratorContext& c)
    : m_scene(c.scene), m_accel(c.accel), m_settings(VoxelConeSettings::fromOptions(c.options, c.scene, c.settings)),
      m_cones(m_settings.cones, float(m_settings.coneAngleDeg * kPi / 180.0)), m_tanHalf(std::tan(m_cones.halfAngle())),
      m_chainCones(m_settings.chainCones, float(m_settings.coneAngleDeg * kPi / 180.0)),
      m_chainTanHalf(std::tan(m_chainCones.halfAngle())) {}

nlohmann::json VoxelConeIntegrator::settingsJson() const {
  nlohmann::json j = m_settings.toJson();
  j["cone_angle"] = m_cones.halfAngle() * 180.0f / kPi;  // the default's value when it was 0
  return j;
}

nlohmann::json VoxelConeIntegrator::statsJson() const {
  nlohmann::json j = m_stats;
  j["field_bytes"] = m_field.memoryBytes();
  j["hit_photon_bytes"] = m_hitPhotons.memoryBytes();
  j["hit_map_photons"] = m_hitPhotons.size();
  j["hit_cache_entries"] = m_hitPhotons.cacheSize();
  j["hit_cache_estimated"] = m_hitPhotons.cacheEstimated();
  for (int level : m_field.levels()) j["active_voxels"][std::to_string(level)] = m_field.activeVoxels(level);
  return j;
}

void VoxelConeIntegrator::prepare(Progress* progress) { build(false, progress); }

void VoxelConeIntegrator::reseed(uint64_t photonSeed, Progress* progress) {
  m_settings.photons.seed = photonSeed;
  build(m_tracer.has_value() && m_settings.voxel.causticLevel == 0, progress);
}

PhotonMaps VoxelConeIntegrator::tracePhotonsForView(Progress* progress) {
  m_stats = nlohmann::json::object();
  // Suns and skies emit from a disc across the scene's bounding sphere, mostly onto what no
  // gather reads (the ground around a house): distant_aim of their photons go to the sphere
  // around most of what the gathers read instead.
  if (m_settings.distantAim > 0.0 && (m_scene.environment || !m_scene.directionalLights.empty())) {
    const Sphere target =
        SeenRegion::readSphere(m_scene, m_accel, m_scene.render.width, m_scene.render.height, kDistantQuantile);
    m_settings.photons.distantTarget = target;
    m_settings.photons.distantShare = m_settings.distantAim;
    m_stats["distant_target"] = {{"center", {target.center.x, target.center.y, target.center.z}},
                                 {"radius", target.radius}};
  }
  PhotonSettings pilot = m_settings.photons;
  const bool guided = m_settings.photonTarget > 0 && m_settings.guideFloor > 0.0 && m_settings.guideFloor < 1.0;
  // The pilot's photons are unguided; each names the primary sample it left from.
  pilot.recordSamples = guided;
  PhotonMaps maps = tracePhotons(m_scene, m_accel, pilot, progress);
  if (m_settings.photonTarget == 0) return maps;
  // The cells the camera's gathers read: cubes of a 64th of the scene's bounding-sphere
  // diameter, about the photon estimate's search radius (hit_radius).
  Timer t;
  const float cell = std::max(2.0f * m_scene.boundingSphere().radius / 64.0f, 1e-30f);
  const SeenRegion seen(m_scene, m_accel, m_scene.render.width, m_scene.render.height, cell);
  // The estimates leave out the photons in the cells the gathers read but on sides they do not
  // (a roof above a seen ceiling), and the sky's own outside those cells (most of a sky's and a
  // sun's land on roofs and ground outside: tools/make_gltf_room.py's room held 1.6M photons in
  // its estimate, 142 MB, and took 0.9 s to build it). The region is dilated by a cell: it is a
  // sample of what the gathers read.
  auto region = std::make_shared<SeenRegion>(seen);
  region->dilate();
  m_settings.hitEstimate.region = std::move(region);
  // The photons counted: with direct light by shadow rays, those that bounced (the sky's own,
  // where its light at hits comes from photons, crowd where it shines in and are not the ones
  // the dim parts of a room lack: counted, a room lit through a window got a third of the
  // photons, and 32x32 blocks of its ceiling moved by up to 50% from photon seed to seed).
  PhotonRadianceSettings estimate = m_settings.hitEstimate;
  estimate.skyDirect = false;
  std::vector<size_t> usefulStores;
  uint64_t inSeen = 0;
  const auto countUseful = [&] {
    usefulStores.clear();
    for (size_t i = 0; i < maps.global.size(); ++i) {
      const Photon& p = maps.global[i];
      if (estimate.keeps(p) && seen.contains(p.position, p.normal)) usefulStores.push_back(i);
    }
    inSeen = usefulStores.size();
  };
  countUseful();
  // A pilot too small to shape a guide, where the pass it would guide is far larger (a room lit
  // through a window: 124 of 10k pilot photons of use, for a pass of 2M): once more, with enough
  // photons for kPilotUseful, at most an eighth of the most allowed. sky-room then traces 251k
  // + 435k photons for its target, tools/make_gltf_room.py's room 251k + 709k (the grid guide
  // before the tree: 96k + 445k and 251k + 1.68M).
  if (guided && double(inSeen) < kPilotUseful) {
    const double perPhoton =
        double(std::max<uint64_t>(inSeen, 1)) / double(std::max<uint64_t>(maps.stats.emittedGlobal, 1));
    const double mainPass = std::min(double(m_settings.maxPhotons), double(m_settings.photonTarget) / perPhoton);
    const double bigger = std::min({kPilotUseful / perPhoton, double(m_settings.maxPhotons) / 8.0, mainPass / 8.0});
    if (bigger > 2.0 * double(maps.stats.emittedGlobal)) {
      pilot.photons = (uint64_t(std::ceil(bigger)) + 1023) / 1024 * 1024;
      maps = tracePhotons(m_scene, m_accel, pilot, progress);
      countUseful();
    }
  }
  m_stats["seen_cells"] = seen.cells();
  m_stats["pilot_photons"] = {{"emitted", maps.stats.emittedGlobal}, {"stored", maps.global.size()}, {"seen", inSeen}};
  if (inSeen < m_settings.photonTarget) {
    // The share the pilot put in the seen cells sets the count (5% over, whole blocks of 1024);
    // none at all: the most allowed.
    const double emitted = double(std::max<uint64_t>(maps.stats.emittedGlobal, 1));
    double share = double(inSeen) / emitted;
    PhotonSettings more = m_settings.photons;
    // Guided by the pilot where that is worth it: the effective number of useful photons per
    // photon (their weights differ) at least a quarter above the unguided share. The count is
    // then the one the guide's own share of useful photons asks for (the target counts photons;
    // from the effective share the sky-room stored 755k for a target of 200k).
    const std::vector<EmissionGuide::Useful> useful =
        guided ? usefulEmissions(maps, usefulStores) : std::vector<EmissionGuide::Useful>();
    if (guided && double(useful.size()) >= kGuideSplit) {
      const std::vector<double> edges = lightChoiceEdges(m_scene);
      auto guide = std::make_shared<EmissionGuide>(
          EmissionGuide::fromUseful(useful, edges, m_settings.guideFloor, kGuideSplit, kGuideMaxRatio));
      double usefulPer = 0.0, effectivePer = 0.0;
      EmissionGuide::heldOutYield(useful, edges, m_settings.guideFloor, kGuideSplit, kGuideMaxRatio, emitted, usefulPer,
                                  effectivePer);
      m_stats["photon_guide"] = {{"leaves", guide->leaves()},
                                 {"unguided_share", share},
                                 {"expected_share", usefulPer},
                                 {"expected_effective_share", effectivePer}};
      if (effectivePer > 1.25 * share) {
        more.guide = guide;
        share = usefulPer;
      }
      m_stats["photon_guide"]["used"] = bool(more.guide);
    }
    const double wanted = share > 0.0 ? 1.05 * double(m_settings.photonTarget) / share : double(m_settings.maxPhotons);
    more.photons = std::min<uint64_t>(m_settings.maxPhotons, (uint64_t(std::ceil(wanted)) + 1023) / 1024 * 1024);
    if (more.photons > maps.stats.emittedGlobal || more.guide) {
      maps = tracePhotons(m_scene, m_accel, more, progress);
      inSeen = seen.count(maps.global, estimate);
    }
  }
  std::vector<EmissionSample>().swap(maps.globalSamples);
  m_stats["seen_photons"] = inSeen;
  m_stats["seen_seconds"] = t.seconds();
  return maps;
}

void VoxelConeIntegrator::addLampPass(std::vector<Photon>& near, uint64_t emitted, Progress* progress) {
  // Where a sky or a sun takes most of the photons, the lamps' few light the gathering points
  // from their surroundings through a thin map (tools/make_gltf_room.py --held-out: 14k of 2M
  // photons left its lamp, and with edge_fit alone the top of the wall above its window still
  // came out 1.10 of Cycles at two of eight seeds): a pass of the lamps' own photons makes them up
  // to lamp_photons. Both passes estimate the same light; each weighs in by its share of the lamp
  // photons (by the power they are chosen by: a guided main pass may have sent more).
  const double lampShare = lampPhotonShare(m_scene);
  const double fromMain = lampShare * double(emitted);
  const double wanted = double(m_settings.lampPhotons);
  if (!(lampShare > 0.0) || !(fromMain < wanted / kNearLampStarved)) return;
  PhotonSettings lamps = m_settings.photons;
  lamps.photons = std::min<uint64_t>(m_settings.maxPhotons, uint64_t(std::ceil(wanted - fromMain) + 1023) / 1024 * 1024);
  lamps.causticPhotons = 0;
  lamps.guide.reset();
  lamps.recordSamples = false;
  lamps.localOnly = true;
  lamps.seed = mixBits(m_settings.photons.seed ^ 0x6c616d7073ULL);
  const PhotonMaps more = tracePhotons(m_scene, m_accel, lamps, progress);
  const float mainWeight = float(fromMain / (fromMain + double(lamps.photons)));
  for (Photon& p : near) p.power *= mainWeight;
  for (Photon p : nearPhotons(more)) {
    p.power *= 1.0f - mainWeight;
    near.push_back(p);
  }
  m_stats["near_light"]["lamp_pass"] = {{"emitted", lamps.photons}, {"from_main", fromMain}, {"seconds", more.stats.seconds}};
}

std::vector<Photon> VoxelConeIntegrator::nearPhotons(const PhotonMaps& maps) const {
  std::vector<Photon> near;
  if (!m_proximity) return near;
  // Estimated only at gathering points, the surfaces the camera sees (through mirrors and
  // glass): the photons within a search radius of them (most of those that left a lamp's
  // surroundings stay there: 323k of 895k in tools/make_gltf_room.py's room, bouncing in the
  // 2 cm between its lamp and the ceiling).
  SeenRegion visible(m_scene, m_accel, m_scene.render.width, m_scene.render.height, m_settings.hitEstimate.maxRadius,
                     m_scene.render.width, m_scene.render.height, 0);
  visible.dilate();
  for (const Photon& p : maps.global)
    if (p.nearShare > 0.0f && visible.contains(p.position, p.normal)) {
      near.push_back(p);
      near.back().power *= p.nearShare;
    }
  return near;
}

void VoxelConeIntegrator::build(bool keepVoxels, Progress* progress) {
  Timer total;
  if (!m_settings.fieldPath.empty() && !keepVoxels) {
    // A field read back (voxelize -o): its light, its settings; no photons traced.
    m_tracer.reset();
    m_hitPhotons = PhotonRadiance();
    m_nearPhotons = PhotonRadiance();
    m_proximity.reset();
    m_field = VoxelField::read(m_settings.fieldPath);
    m_field.checkScene(m_scene, m_settings.fieldPath);
    const uint64_t budget = m_settings.voxel.memoryBudgetBytes;
    m_settings.voxel = m_field.settings();
    m_settings.voxel.memoryBudgetBytes = budget;
    m_settings.photons.photons = m_settings.photons.causticPhotons = 0;
    m_glossyCaustics = PhotonRadiance();
    m_glossyCausticByPhotons = false;
    m_stats = nlohmann::json::object();
    m_stats["field_read_seconds"] = total.seconds();
    m_stats["prepare_seconds"] = total.seconds();
    m_stats["peak_rss_bytes_after_prepare"] = peakRssBytes();
    startTracer();
    return;
  }
  if (m_settings.nearLight != 0.0f && !m_proximity) {
    const float radius = m_settings.nearLight > 0.0f ? m_settings.nearLight
                                                     : float(kNearLightScale * SeenRegion::meanGatherDistance(
                                                                                   m_scene, m_accel, m_scene.render.width,
                                                                                   m_scene.render.height));
    if (radius > 0.0f) m_proximity = std::make_shared<LightProximity>(m_scene, radius);
    if (m_proximity && m_proximity->empty()) m_proximity.reset();
  }
  m_settings.photons.proximity = m_proximity;
  const PhotonMaps maps = tracePhotonsForView(progress);
  m_stats.update(maps.stats.toJson());
  // Caustics on glossy surfaces from the caustic pass's photons where it ran (a scene with
  // mirrors or glass); else the glossy cones find them through the mirrors.
  m_glossyCausticByPhotons = maps.stats.emittedCaustic > 0 && m_settings.hitGather;
  m_glossyCaustics = PhotonRadiance(m_scene, m_accel, maps.glossyCaustic, m_settings.hitEstimate);
  m_stats["photon_trace_seconds"] = maps.stats.seconds;
  m_tracer.reset();
  if (m_settings.hitPhotons) {
    Timer kd;
    m_hitPhotons = PhotonRadiance(m_scene, m_accel, maps, m_settings.hitEstimate);
    std::vector<Photon> near = nearPhotons(maps);
    if (m_proximity) {
      addLampPass(near, maps.stats.emittedGlobal, progress);
      m_stats["near_light"]["radius"] = m_proximity->radius();
      m_stats["near_light"]["photons"] = near.size();
    }
    // Few of those photons reach far from the lamps, and there their discs are wide: at an
    // edge the part's mean is far from the point's light (PhotonRadianceSettings::edgeFit).
    PhotonRadianceSettings nearEstimate = m_settings.hitEstimate;
    nearEstimate.edgeFit = m_settings.nearEdgeFit;
    m_nearPhotons = PhotonRadiance(m_scene, m_accel, std::move(near), nearEstimate);
    m_stats["hit_photons_seconds"] = kd.seconds();
  }
  const uint64_t photonPeak = peakRssBytes();
  // Cones whose exact hits take the photons read no voxel: the main grid then keeps only the
  // caustic photons, which the caustic grid's lookups at shading points need.
  PhotonMaps causticOnly;
  const bool conesReadPhotons = m_settings.hitGather && m_settings.hitPhotons && m_settings.view != View::Field;
  if (conesReadPhotons) causticOnly.caustic = maps.caustic;
  const PhotonMaps& held = conesReadPhotons ? causticOnly : maps;
  VoxelField::BuildStats built;
  if (keepVoxels) {
    m_field.relight(held, progress, &built);
  } else {
    m_tracer.reset();
    m_field = VoxelField::build(m_scene, m_settings.voxel, maps, held, progress, &built);
  }
  m_stats["voxelize_seconds"] = built.voxelizeSeconds;
  m_stats["inject_seconds"] = built.injectSeconds;
  m_stats["mips_seconds"] = built.mipsSeconds;
  // The process's peak resident set after each stage (its high-water mark so far).
  m_stats["peak_rss_bytes_after"] = {{"photons", photonPeak},
                                     {"voxelize", keepVoxels ? photonPeak : built.peakAfterVoxelize},
                                     {"inject", built.peakAfterInject},
                                     {"mips", built.peakAfterMips}};
  m_stats["prepare_seconds"] = total.seconds();
  startTracer();
}

void VoxelConeIntegrator::startTracer() {
  m_tracer.emplace(m_scene, m_accel, m_field, m_settings, &m_hitPhotons, m_proximity.get());
  const int causticLevel = m_field.settings().causticLevel;
  m_causticVoxel = causticLevel > 0 ? float(m_field.voxelSize(causticLevel)) : m_tracer->finestVoxel();
}

Vec3 VoxelConeIntegrator::gatherDiffuse(const SurfaceHit& sh, const Vec3& woWorld, float u, bool chain,
                                         bool untextured) const {
  const ConeSet& cones = chain ? m_chainCones : m_cones;
  const float tanHalf = chain ? m_chainTanHalf : m_tanHalf;
  Material textured;
  const Material& mat = m_scene.materialAt(sh, textured);
  if (untextured && mat.albedoTexture >= 0) textured.albedo = Vec3(1.0f);
  const Vec3 ng = glm::dot(sh.geomNormal, woWorld) >= 0.0f ? sh.geomNormal : -sh.geomNormal;
  const Frame frame(sh.shadingNormal);
  const Vec3 wo = frame.toLocal(woWorld);
  // gather = hit: the axes (each cone one exact ray) a stratified cosine-distributed set, a
  // Hammersley set shifted by a hash of u (Cranley-Patterson) through the cosine map, each
  // weighted f(wo, axis) * pi / N: unbiased for light of any shape. The march's cone set
  // (cone_set.h) turned by the angle 2 pi u about the normal, each cone weighted
  // f(wo, axis) * pi * w_i (albedo * w_i for a Lambertian surface), integrates in azimuth alone,
  // at the set's fixed elevations: light that arrives in a narrow band of elevation is found
  // where a cone's elevation meets it, at its whole cell's weight (the sky through a 5 cm slot
  // came out 7% dark at one place, VoxelCone.SkyThroughASlotMatchesLambertsFormula).
  const float rotation = 2.0f * kPi * u;
  const float cr = std::cos(rotation), sr = std::sin(rotation);
  const Frame geo(ng);
  // The light samples at the cones' hits: a Hammersley set over the cones, shifted by a hash of
  // u (Cranley-Patterson), so the gather's shadow rays spread over the lights' area.
  uint32_t uBits;
  std::memcpy(&uBits, &u, sizeof uBits);
  const uint64_t key = mixBits(uint64_t(uBits) + 0x9e3779b97f4a7c15ULL);
  const Vec2 shift(float(key >> 40) * 0x1p-24f, float((key >> 16) & 0xffffffu) * 0x1p-24f);
  const uint64_t dirKey = mixBits(key);
  const Vec2 dirShift(float(dirKey >> 40) * 0x1p-24f, float((dirKey >> 16) & 0xffffffu) * 0x1p-24f);
  const size_t n = cones.cones().size();
  const bool stratified = m_settings.hitGather;
  Vec3 indirect(0.0f);
  for (size_t i = 0; i < n; ++i) {
    const Cone& cone = cones.cones()[i];
    const Vec3 d =
        stratified ? geo.toWorld(sampleCosineHemisphere(shiftedHammersley(i, n, dirShift)))
                   : geo.toWorld(Vec3(cr * cone.axis.x - sr * cone.axis.y, sr * cone.axis.x + cr * cone.axis.y, cone.axis.z));
    const float coneWeight = stratified ? 1.0f / float(n) : cone.weight;
    const Vec3 f = mat.type == MaterialType::Lambertian ? mat.albedo : kPi * bsdfEvalBase(mat, wo, frame.toLocal(d));
    if (isBlack(f)) continue;
    const Vec2 lightU = shiftedHammersley(i, n, shift);
    indirect += coneWeight * f * m_tracer->trace(sh.position, sh.positionError, ng, d, tanHalf, lightU, 0,
                                                  m_settings.skyByCones, nullptr, nullptr, true);
  }
  // What the cones left of the light from surfaces beside the lamps: the photons that came from
  // there, estimated here (reflected as a Lambertian surface of the base's reflectance).
  if (!m_nearPhotons.empty()) {
    const Vec3 f = mat.type == MaterialType::Lambertian ? mat.albedo : diffuseReflectance(mat);
    indirect += f * kInvPi * m_nearPhotons.irradiance(sh, ng);
  }
  return indirect;
}

Vec3 VoxelConeIntegrator::gatherDeferred(const DeferredGather& g) const {
  // A textured albedo taken as 1: the light is filtered across the texture's detail and
  // multiplied by the albedo after (IndirectSplit::albedo).
  return gatherDiffuse(g.hit, g.wo, g.u, false, true);
}

Vec3 VoxelConeIntegrator::shade(const SurfaceHit& sh, const Vec3& woWorld, Sampler& sampler, IndirectSplit* split,
                                 RadianceTerms* terms, const Vec3& weight, int depth) const {
  Material textured;
  const Material& mat = m_scene.materialAt(sh, textured);
  // A viewpoint on the viewer's side, clear of the surface's own voxels of size `voxel` (as the
  // cones' apex in ConeTracer::trace).
  const auto viewFrom = [&](const Vec3& dir, float voxel) { return sh.position + dir * (kApexLift * voxel); };
  // The parts, summed in this order: direct, then caustic, then indirect.
  Vec3 direct(0.0f), caustic(0.0f), indirect(0.0f);
  const auto result = [&] {
    if (terms) {
      terms->direct += weight * direct;
      terms->caustic += weight * caustic;
      terms->indirect += weight * indirect;
    }
    return direct + caustic + indirect;
  };
  if (m_settings.view == View::Field) {
    indirect = m_field
                   .coneSample(sh.position, float(m_tracer->finestLevel()), -woWorld,
                               viewFrom(woWorld, m_tracer->finestVoxel()))
                   .radiance;
    return result();
  }
  // A glossy lobe's cones (gather = hit) find the lights too: their emission and the light
  // samples' are weighted by the power heuristic (glossyMis), which a narrow lobe under a large
  // light needs (light samples alone left a plate of roughness 0.05 in a furnace 3% dark at 16
  // spp, noise: 1.5% at 64).
  const bool glossyMis = m_settings.hitGather && m_settings.view == View::Full && !mat.isDelta() &&
                         !mat.hasDiffuseBase();
  if (m_settings.view == View::Full || m_settings.view == View::Direct)
    direct = estimateDirectLight(m_scene, m_accel, sh, woWorld, sampler, m_settings.lightSamples,
                                 !(m_settings.skyByCones && mat.hasDiffuseBase()),
                                 glossyMis ? glossyLobeCones(mat.roughness) : 0);
  if (m_settings.view == View::Direct) return result();
  // Cones on the pixel's first `gathers` samples only, weighted to keep the pixel's mean.
  float gatherWeight = 1.0f;
  const uint32_t gathers = uint32_t(m_settings.gathers);
  if (gathers > 0 && sampler.samplesPerPixel() > gathers)
    gatherWeight = sampler.sampleIndex() < gathers ? float(sampler.samplesPerPixel()) / float(gathers) : 0.0f;
  // The side of the surface the viewer is on.
  const bool front = glm::dot(sh.geomNormal, woWorld) >= 0.0f;
  const Vec3 ng = front ? sh.geomNormal : -sh.geomNormal;
  const Frame frame(sh.shadingNormal);
  const Vec3 wo = frame.toLocal(woWorld);
  // A one-sided surface seen from behind: no caustics, no cones (its direct light is 0 too).
  if (mat.blackFrom(wo.z)) return result();
  if (mat.hasDiffuseBase()) {
    // A rough coat's glossy reflection: cones over the coat's lobe alone, on every sample (as
    // the glossy materials below); a smooth coat's is the delta chain's.
    if (mat.type == MaterialType::RoughPlastic && m_settings.view != View::Caustic)
      indirect += gatherLobe(sh, frame, wo, mat, sampler, true, nullptr, nullptr);
    if (m_settings.view != View::Indirect) caustic = m_field.causticRadiance(sh.position, viewFrom(ng, m_causticVoxel));
    if (m_settings.view == View::Caustic) return result();
    if (split) {
      split->valid = true;
      split->position = sh.position;
      split->normal = ng;
      split->material = sh.material;
      // The deferred gather takes a textured albedo as 1: the albedo here multiplies the
      // filtered light.
      if (mat.albedoTexture >= 0) split->albedo = mat.albedo;
    }
    if (gatherWeight == 0.0f) return result();
    const float u = sampler.uniform();
    // With the filter the cones wait until renderImage knows whether this pixel needs them.
    if (split) {
      split->deferred = true;
      split->gather = {sh, woWorld, u, gatherWeight};
      return result();
    }
    indirect += gatherWeight * gatherDiffuse(sh, woWorld, u, depth > 0);
    return result();
  }
  if (m_settings.view == View::Caustic) return result();
  // Glossy: cones over the lobe on every sample (a pixel's gathering samples alone left the
  // rough gold dragon at relMSE 0.012 where path needs 10 spp for it).
  Vec3 found(0.0f);
  indirect = gatherLobe(sh, frame, wo, mat, sampler, false, glossyMis ? &found : nullptr,
                        m_settings.hitGather && m_settings.view == View::Full && !m_glossyCausticByPhotons
                            ? &caustic
                            : nullptr);
  direct += found;
  // The photons' estimate changes little across a pixel: taken on the gathering samples only,
  // weighted as the cones' gathers are (on every sample it cost 25% of glossy-room's time).
  if (m_glossyCausticByPhotons && m_settings.view == View::Full && gatherWeight > 0.0f)
    caustic = gatherWeight * m_glossyCaustics.reflected(sh, ng, woWorld);
  return result();
}

int VoxelConeIntegrator::glossyLobeCones(float roughness) const {
  const float r = roughness / m_settings.glossySwitch;
  return r <= 1.0f ? 1 : int(std::min(float(m_settings.glossyCones), std::ceil(r * r)));
}

Vec3 VoxelConeIntegrator::gatherLobe(const SurfaceHit& sh, const Frame& frame, const Vec3& wo, const Material& mat,
                                     Sampler& sampler, bool coat, Vec3* emission, Vec3* caustic) const {
  // The lobe split into n strata of equal probability under the BSDF's own sampling map
  // (a Hammersley set of n points over its 2D square, shifted by the pixel sample's numbers:
  // Cranley-Patterson), one cone per stratum along the direction its point maps to, weighted
  // f cos / (n pdf): each stratum's share of the lobe's integral. n grows with the lobe's solid
  // angle (roughness^2), so every cone covers about what one cone covers at glossy_switch; a
  // lobe no wider than that takes one exact ray. The choice of lobe (a dielectric's reflection
  // or refraction) is stratified over the cones likewise, and so are the light samples at
  // their hits. Unbiased for any n: every cone's direction is marginally the BSDF's sample.
  const int n = glossyLobeCones(mat.roughness);
  const float ucShift = sampler.uniform();
  const Vec2 shift = sampler.uniform2();
  const Vec2 lightShift = sampler.uniform2();
  // Roughness is in (0, 1]. Below 0.01 a marched cone would stay one finest voxel wide for over
  // 100 steps; the lookups cannot resolve less than a voxel anyway.
  const float tanHalf = std::max(mat.roughness, 0.01f);
  Vec3 L(0.0f), Le(0.0f), C(0.0f);
  for (int i = 0; i < n; ++i) {
    // The direction's pair: the Hammersley set jittered within its strata ((i + shift.x) / n),
    // not rotated as shiftedHammersley rotates it (which broke the set's pairing where it wraps:
    // glossy-room 35.12 against 35.42 dB).
    Vec2 u((float(i) + shift.x) / float(n), float(sobolDim0(uint32_t(i))) * 0x1p-32f + shift.y);
    u = glm::min(u - glm::floor(u), Vec2(kOneMinusEpsilon));
    const Vec2 lightU = shiftedHammersley(size_t(i), size_t(n), lightShift);
    // The lobe's choice stratified too: the Hammersley set's first coordinate, shifted apart.
    const float uc = shiftedHammersley(size_t(i), size_t(n), Vec2(ucShift, 0.0f)).x;
    BsdfSample bs;
    if (!(coat ? coatSample(mat, wo, u, bs) : bsdfSample(mat, wo, uc, u, bs)) || isBlack(bs.weight)) continue;
    const Vec3 d = frame.toWorld(bs.wi);
    const Vec3 side = glm::dot(d, sh.geomNormal) >= 0.0f ? sh.geomNormal : -sh.geomNormal;
    if (!(glm::dot(side, d) > 0.0f)) continue;
    std::optional<SurfaceHit> axis;
    Vec3 throughDelta(0.0f);
    L += bs.weight * m_tracer->trace(sh.position, sh.positionError, side, d, tanHalf, lightU, 0,
                                     coat && m_settings.skyByCones, emission ? &axis : nullptr,
                                     caustic ? &throughDelta : nullptr);
    if (emission && !bs.delta)
      Le += bs.weight * misWeightedEmission(m_scene, sh, d, bs.pdf, n, m_settings.lightSamples, axis ? &*axis : nullptr);
    if (caustic) C += bs.weight * throughDelta;
  }
  if (emission) *emission = Le / float(n);
  if (caustic) *caustic = C / float(n);
  return L / float(n);
}

Vec3 VoxelConeIntegrator::trace(const Ray& ray, Sampler& sampler, IndirectSplit* split, RadianceTerms* terms) const {
  if (!m_tracer) throw Error("voxcone: li() before prepare()");
  // Emission is seen directly or through delta bounces (shadow rays sample it elsewhere).
  const bool emission = m_settings.view == View::Full || m_settings.view == View::Direct;
  // Only the camera ray's own first hit is split off for the screen-space filter.
  return traceDeltaChains(
      m_scene, m_accel, ray, sampler, m_settings.maxDepth, m_settings.maxDepth, emission,
      [this, split, terms](const SurfaceHit& sh, const Vec3& wo, Sampler& px, int depth, const Vec3& weight) {
        return shade(sh, wo, px, depth == 0 ? split : nullptr, terms, weight, depth);
      },
      terms);
}

Vec3 VoxelConeIntegrator::li(const Ray& ray, Sampler& sampler) const { return trace(ray, sampler, nullptr, nullptr); }

Vec3 VoxelConeIntegrator::liTerms(const Ray& ray, Sampler& sampler, IndirectSplit* split, RadianceTerms& terms) const {
  if (split) *split = IndirectSplit();
  return trace(ray, sampler, split, &terms);
}

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
  if (m_settings.filterReach > 0.0f) b.reach = surfaceReach(b, m_settings.filterRadius, m_settings.filterReach);
}

bool VoxelConeIntegrator::linkedPoints(const Vec3& from, const Vec3& to) const {
  Ray r;
  r.origin = from;
  r.dir = to - from;
  r.tMax = 1.0f;
  return !m_accel.occluded(r);
}

bool VoxelConeIntegrator::glintsVary(const Ray* probes, int count) const {
  // Yes where a probe meets glass (refraction bends the pixel's rays apart), sees a light through
  // mirrors, or where the probes' first mirrors are not one plane (a curved mirror spreads the
  // pixel's reflections); a flat mirror that shows no light shows it nowhere in the pixel.
  std::optional<Vec3> plane;
  Sampler unused(SamplerKind::Independent, 0, 0);  // every lobe is followed: no random numbers
  for (int i = 0; i < count; ++i) {
    SurfaceHit sh;
    if (!intersectSurface(m_scene, m_accel, probes[i], sh) || !m_scene.materials[sh.material].isDelta()) continue;
    if (plane && glm::dot(*plane, sh.shadingNormal) < 0.9999f) return true;
    plane = sh.shadingNormal;
    bool glass = false;
    RadianceTerms terms;
    traceDeltaChains(
        m_scene, m_accel, probes[i], unused, m_settings.maxDepth, m_settings.maxDepth, true,
        [](const SurfaceHit&, const Vec3&, Sampler&, int, const Vec3&) { return Vec3(0.0f); }, &terms, 0, 1.0f,
        Vec3(1.0f), &glass);
    if (glass || maxComponent(terms.glint) > 0.0f) return true;
  }
  return false;
}

Vec3 VoxelConeIntegrator::liGlint(const Ray& ray, Sampler& sampler) const {
  if (m_settings.view != View::Full && m_settings.view != View::Direct) return Vec3(0.0f);
  // One lobe at each dielectric (chosen by weight): a glint sample is a few rays, and many of
  // them sample the pixel better than a few that split.
  RadianceTerms terms;
  traceDeltaChains(
      m_scene, m_accel, ray, sampler, m_settings.maxDepth, 0, true,
      [](const SurfaceHit&, const Vec3&, Sampler&, int, const Vec3&) { return Vec3(0.0f); }, &terms);
  return terms.glint;
}

Vec3 VoxelConeIntegrator::liSplit(const Ray& ray, Sampler& sampler, IndirectSplit& split) const {
  split = IndirectSplit();
  return trace(ray, sampler, &split, nullptr);
}

}  // namespace voxcone

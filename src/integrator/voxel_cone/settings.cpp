// voxcone's options: defaults, ranges and the measurements that chose them.

#include "voxcone/integrator/voxel_cone/settings.h"

#include "../options.h"
#include "voxcone/core/error.h"
#include "voxcone/scene/environment.h"
#include "voxcone/scene/scene.h"

#include <algorithm>
#include <limits>

namespace voxcone {

namespace {
/// Defaults chosen by time to error against path at 4096 spp (cornell-box, cornell-dragon and
/// cornell-dragon-glass, 256x256, 2 threads; docs/method.md ("Where voxcone's time goes") has the
/// figures). Level 5: with 10k photons a finer level has fewer photons per voxel. At 4 spp level
/// 5 / 6 give cornell-box 35.87 / 35.86 dB in 0.11 / 0.13 s, cornell-dragon 36.13 / 35.69 dB, the
/// glass dragon 31.78 / 30.94 dB (2 spp: 29.73 / 29.09 dB); study levels (dragon, 16 spp) 38.65 /
/// 37.92 / 36.90 / 35.40 dB at levels 5 / 6 / 7 / 8; only converged cornell-box prefers 6 (64
/// spp: 38.97 / 39.07 dB). (With 100k photons and cones on every sample level 6 was best: the
/// dragon lost 0.9 dB at level 5.) Indirect light: one gathering pixel per 4x4 block, one gather there
/// (its first sample), the filter of radius 12 filling the rest. Cornell-box at 4 spp (total s,
/// dB): spacing 3 / 4 / 5 with filter 12 and 1 gather 0.21 / 0.17 / 0.17 s, 36.13 / 35.86 /
/// 35.45 dB (2 gathers: +0.4-0.6 dB for +0.02-0.03 s); filter 8 / 10 / 12 at spacing 4: 35.22 /
/// 35.64 / 35.86 dB in the same time; 3 spp 33.45 dB (direct light needs 4 stratified samples:
/// 25.4 / 29.6 / 35.5 / 42.5 dB at 1 / 2 / 4 / 8 spp of it alone).
constexpr int kDefaultLevel = 5;
constexpr int kDefaultGathers = 1;
constexpr int kDefaultFilterRadius = 12;
constexpr int kDefaultGatherSpacing = 4;
/// Cones per gather: with gather = "hit" (the default) each is one exact ray and one photon
/// estimate at its hit; with "march", 6 marched cones (their defaults' measurements above).
constexpr int kDefaultHitCones = 32;
constexpr int kDefaultMarchCones = 6;
/// The filter's reach in distances to the nearest surface that meets a pixel's own. Measured on
/// tools/make_gltf_room.py's four rooms against Cycles (seeds 0-7, 32x32 blocks; with 4 hit light
/// samples), the seeds with a block beyond 10% in room / --held-out / -2 / -3: no limit 0 / 1 /
/// 0 / 1, 1: none (worst 1.100 / 1.074 / 1.098 / 1.098), 2: none (1.100 / 1.090 / 1.096 /
/// 1.098); filter 0 (a gather at every pixel) put --held-out-3's wall-ceiling row at 1.01 where
/// the unlimited filter put it at 1.03-1.05. The pixels it leaves without a gather in reach gather
/// themselves: --held-out-3 runs 5254 gathers against 4035 unlimited (0.46 s of its 1.6 s).
constexpr double kDefaultFilterReach = 1.0;
/// Shadow rays at each cone's hit. Measured on --held-out-3 (its lamp 5 cm under the ceiling,
/// behind the camera; photon seed fixed, pixel seeds 0-5): the standard deviation of a top-two-
/// rows 32x32 block 0.0219 / 0.0144 / 0.0141 at 1 / 4 / 8 (128 cones instead of 32: 0.0133), the
/// render 1.42 / 1.52 / 1.64 s.
constexpr int kDefaultHitLightSamples = 4;
/// The share of a distant light's photons aimed at what the gathers read. Measured at seeds 0-7
/// on tools/make_gltf_room.py's room against Cycles (32x32 blocks) and at seeds 1-3 on sky-room
/// against path (4x4 cells): 0 left 3 of 8 seeds with a block out of 10% (worst 1.152), 0.5 and
/// 0.75 none (worst 1.086, 1.093), 0.9 one (1.217); sky-room's worst cells 0.96-1.02 at 0,
/// 1.02-1.06 at 0.5, 0.98-1.09 at 0.75 (the photons the whole disc still sends, through the
/// window from the ground, weigh 1 / (1 - share) as much).
constexpr double kDefaultDistantAim = 0.5;
/// Cones per gather at a hit behind mirrors and glass: such a pixel gathers itself (the filter
/// cannot fill it), so 32 cones there made the glass dragon 13.6 s (11.1 s of it its samples).
constexpr int kDefaultChainCones = 8;
/// Cones over a glossy lobe (rough conductors, dielectrics and coats seen from the camera or
/// through mirrors): ceil((roughness / switch)^2) of them, at most glossy_cones, each over one
/// stratum of the lobe; one exact ray at roughness `switch` and below. Measured on glossy-room
/// (a GGX 0.25 aluminium wall, a 0.2 rough dielectric floor; 256x256, 16 spp, 2 threads,
/// against path at 4096 spp), cones at most / switch: 1 cone 33.19 dB in 2.00 s; 2 / 0.1 34.56
/// dB; 4 / 0.2 (2 and 1 cones) 33.41 dB in 2.20 s; 4 / 0.15 (3 and 2) 34.64 dB; 4 / 0.1 (4 and
/// 4) 35.40 dB in 2.67 s; 8 / 0.1 (7 and 4) 35.45 dB in 3.08 s; 8 / 0.05 35.97 dB in 3.94 s;
/// 16 / 0.05 36.21 dB in 5.87 s; 32 / 0.05 36.17 dB in 7.89 s. Path needs about 18 s for 35.4
/// dB: 4 / 0.1 has the best ratio (0.15); the worst 4x4 cell is 0.94 from 4 cones on.
constexpr int kDefaultGlossyCones = 4;
constexpr double kDefaultGlossySwitch = 0.1;
/// Glint samples per camera sample where the scene has mirrors or glass: on the glass dragon
/// (256x256, 16 spp) 0 / 8 / 16 gave relMSE 0.0099 / 0.0048 / 0.0030 in 4.3 / 5.0 / 6.1 s, the
/// light's image in the glass the noise of nearly all of the error.
constexpr int kDefaultGlintSamples = 16;
/// The photon estimate at a cone's exact hit (PhotonRadiance): photons per estimate, and the
/// largest search radius as a fraction of the scene's bounding-sphere radius.
constexpr int kDefaultHitPhotons = 32;
constexpr double kDefaultHitRadius = 0.1;
/// Irradiance precomputed at every 8th photon (PhotonRadiance, Christensen 1999). Measured
/// (256x256, 2 threads): small-objects with every 4th / 8th / 16th photon prepared in 1.35 /
/// 0.94 / 0.62 s and gathered in 0.49 / 0.70 / 1.02 s (farther entries pass the filters less
/// often, and the full estimate runs), without 0.43 and 3.05 s; the glass dragon 7.99 -> 3.98 s
/// at the same 33.5 dB. (While an entry's estimate counted the other entries' photons it was
/// biased low, -3.5% on a uniform floor, and a held-out two-rooms floor came out 0.881 of path
/// with it, 0.938 without; estimated from the other photons only, 0.976 with it.)
constexpr int kDefaultHitCacheStride = 8;
/// Photons in the cells the camera's gathers read (VoxelConeSettings::photonTarget: with direct
/// light at the cones' hits by shadow rays, photons that bounced), and the most photons emitted
/// to get them. At 100k a 4x4 cell of two-rooms-door moved by up to 7% from seed to seed
/// (0.927-1.048 of path over four seeds), at 250k by up to 2.5%; 200k put every cell of the
/// suite, its held-out variants and the Cornell scenes within 4.4% (one seed), at 0.3-0.9 s more
/// per render than 100k.
constexpr int kDefaultPhotonTarget = 200000;
/// With the denoiser after it (RenderSettings::denoise): a quarter of the photons. Measured with
/// tools/race_table.py on the canonical and failure scenes (docs/studies/race): at 2-8 spp
/// voxcone+denoise takes 0.6-0.8x the time for the same error, its worst 4x4 cells within
/// 0.966-1.040 of path's (0.965-1.038 at the default; glossy-room's 0.935 and many-lights' 0.88
/// at 4 spp as at the default).
constexpr int kDenoisedPhotonTarget = 50000;
/// The share of the second pass's photons emitted uniformly when the pilot guides it
/// (EmissionGuide's floor: a photon weighs at most 1 / floor of an unguided one).
constexpr double kDefaultGuideFloor = 0.25;
constexpr int kDefaultMaxPhotons = 2000000;
}  // namespace

const std::vector<std::string>& VoxelConeSettings::mipFilterNames() {
  static const std::vector<std::string> names = {"box", "gaussian"};
  return names;
}

const std::vector<std::string>& VoxelConeSettings::viewNames() {
  static const std::vector<std::string> names = {"full", "direct", "indirect", "caustic", "field"};
  return names;
}

VoxelConeSettings VoxelConeSettings::fromOptions(const nlohmann::json& options, const Scene& scene,
                                                 const RenderSettings& render) {
  VoxelConeSettings out;
  OptionReader r(options, "voxcone");
  constexpr int kMaxInt = std::numeric_limits<int>::max();
  bool anyDelta = false;
  for (const Material& m : scene.materials) anyDelta = anyDelta || m.hasDeltaLobe();
  out.maxDepth = render.maxDepth;

  out.fieldPath = r.text("field", "");
  if (!out.fieldPath.empty())
    for (const char* fixed : {"level", "coarsest_level", "caustic_level", "kernel_sigma", "mip_filter", "photons",
                              "caustic_photons"})
      if (r.has(fixed))
        throw SettingsError(std::string("voxcone.") + fixed + ": the field (voxcone.field) fixes it; give one or the other");

  VoxelSettings& v = out.voxel;
  v.level = r.integer("level", kDefaultLevel, 1, 12);
  v.coarsestLevel = r.integer("coarsest_level", std::min(1, v.level), 0, v.level);
  v.causticLevel = r.integer("caustic_level", anyDelta ? std::min(12, v.level + 1) : 0, 0, 12);
  if (v.causticLevel != 0 && v.causticLevel < v.coarsestLevel)
    throw SettingsError("voxcone.caustic_level: must be 0 or at least coarsest_level");
  v.kernelSigmaVoxels = float(r.number("kernel_sigma", 0.75, 0.05, 16.0));
  v.mipFilter = r.choice("mip_filter", mipFilterNames()) == "gaussian" ? MipFilter::Gaussian : MipFilter::Box;
  // MB (10^6 bytes); 0: no budget; absent: the machine's available memory (VoxelSettings).
  v.memoryBudgetBytes = VoxelSettings::budgetFromMegabytes(r.number("memory_budget_mb", -1.0, 0.0, 1e12));

  uint64_t photons, causticPhotons;
  defaultPhotonCounts(render.photons, render.causticPhotons, kVoxconeDefaultPhotons, kVoxconeDefaultCausticPhotons,
                      photons, causticPhotons);
  PhotonSettings& p = out.photons;
  p.photons = uint64_t(r.integer("photons", int(std::min<uint64_t>(photons, kMaxInt)), 0, kMaxInt));
  p.causticPhotons = uint64_t(r.integer("caustic_photons", int(std::min<uint64_t>(causticPhotons, kMaxInt)), 0, kMaxInt));
  p.seed = render.seed + uint64_t(r.integer("seed", 0, 0, kMaxInt));
  p.maxDepth = std::max(1, render.maxDepth);
  if (!anyDelta || v.causticLevel == 0) p.causticPhotons = 0;
  const bool photonsGiven = r.has("photons") || render.photons > 0 || !out.fieldPath.empty();
  const int target = render.denoise ? kDenoisedPhotonTarget : kDefaultPhotonTarget;
  out.photonTarget = uint64_t(r.integer("photon_target", photonsGiven ? 0 : target, 0, kMaxInt));
  out.maxPhotons = uint64_t(r.integer("max_photons", kDefaultMaxPhotons, 1, kMaxInt));
  // The lamp pass's photons: the photon target. Measured on tools/make_gltf_room.py's five rooms
  // (seeds 0-7, 32x32 blocks against Cycles; the mean over blocks of each block's spread across
  // seeds, the worst block, the median time): half the target 0.0161 / 0.0163 / 0.0142 / 0.0188 /
  // 0.0146, worst 1.0995 / 1.074 / 1.098 / 1.098 / 1.065, 1.39 / 1.67 / 1.66 / 1.59 / 1.6 s; the
  // target 0.0144 / 0.0143 / 0.0130 / 0.0162 / 0.0120, 1.084 / 1.078 / 1.080 / 1.083 / 1.065,
  // 1.54 / 1.86 / 1.98 / 1.89 / 1.74 s; twice it cut the glTF room's spread to 0.0121 in 1.7 s.
  out.lampPhotons = uint64_t(r.integer("lamp_photons", int(out.photonTarget), 0, kMaxInt));
  if (photonsGiven && out.photonTarget > 0)
    throw SettingsError("voxcone.photon_target: the photon count is given (photons); give one or the other");
  out.guideFloor = r.number("photon_guide", kDefaultGuideFloor, 0.0, 1.0);
  out.distantAim = r.number("distant_aim", kDefaultDistantAim, 0.0, 0.99);

  out.hitGather = r.choice("gather", {"hit", "march"}) == "hit";
  out.cones = r.integer("cones", out.hitGather ? kDefaultHitCones : kDefaultMarchCones, 1, 256);
  out.chainCones = r.integer("chain_cones", out.hitGather ? kDefaultChainCones : out.cones, 1, 256);
  out.glossyCones = r.integer("glossy_cones", kDefaultGlossyCones, 1, 64);
  out.glossySwitch = float(r.number("glossy_switch", kDefaultGlossySwitch, 1e-3, 1.0));
  out.coneAngleDeg = r.number("cone_angle", 0.0, 0.0, 89.0);
  out.coneStep = float(r.number("cone_step", 1.0, 0.25, 4.0));
  const float sceneRadius = std::max(0.0f, scene.boundingSphere().radius);
  out.maxDistance = float(r.number("max_distance", 2.0 * double(sceneRadius), 0.0, 1e30));
  out.lightSamples = r.integer("light_samples", 1, 1, 1024);
  out.gathers = r.integer("gathers", kDefaultGathers, 0, 1 << 24);
  out.filterRadius = r.integer("filter", kDefaultFilterRadius, 0, 64);
  out.filterReach = float(r.number("filter_reach", kDefaultFilterReach, 0.0, 1e3));
  out.gatherSpacing = r.integer("gather_spacing", out.filterRadius > 0 ? kDefaultGatherSpacing : 1, 1, 16);
  if (out.gatherSpacing > 1 && out.filterRadius == 0)
    throw SettingsError("voxcone.gather_spacing: above 1 needs the filter (filter > 0) to fill the other pixels");
  out.exactSegment = float(r.number("exact_segment", 32.0, 0.0, 1e6));
  // A field read back has no photons: its cones read it at their hits.
  out.hitPhotons = r.choice("hit_radiance", {"photons", "field"}) == "photons" && out.fieldPath.empty();
  if (!out.fieldPath.empty() && r.has("hit_radiance") && options["hit_radiance"] == "photons")
    throw SettingsError("voxcone.hit_radiance: a field read back (voxcone.field) has no photons; give \"field\" or nothing");
  out.hitDirect = r.choice("hit_direct", {"rays", "photons"}) == "rays";
  out.hitEstimate.indirectOnly = out.hitPhotons && out.hitDirect;
  // The sky's light at a cone's hit: one shadow ray towards it finds a window from the room's
  // far side about as often as the window fills the sky. In a room lit through one
  // (tools/make_gltf_room.py without its lamp; the photons fixed, six render seeds) a 32x32
  // block's standard deviation was a median 6.9% of its mean (at most 18%) with the ray, 2.7%
  // (at most 14%) with the photons that came in through the window.
  out.hitSkyPhotons = r.choice("hit_sky", {"photons", "rays"}) == "photons";
  out.hitEstimate.skyDirect = out.hitEstimate.indirectOnly && scene.environment && out.hitSkyPhotons;
  // "auto": cones under a constant sky, rays under a map (a map's small bright patch read at a
  // few cone axes per pixel put cells off by up to 47%; sky-room, a constant sky through a
  // window, gave 29.2 dB by cones, 26.9 by rays at the same worst cell).
  const std::string sky = r.choice("sky_light", {"auto", "cones", "rays"});
  out.skyByCones = out.hitGather && (sky == "cones" || (sky == "auto" && scene.environment && scene.environment->isConstant()));
  out.hitLightSamples = r.integer("hit_light_samples", kDefaultHitLightSamples, 1, 64);
  out.glintSamples = r.integer("glint_samples", anyDelta ? kDefaultGlintSamples : 0, 0, 4096);
  out.hitEstimate.k = r.integer("hit_photons", kDefaultHitPhotons, 1, 4096);
  out.hitEstimate.maxRadius = float(r.number("hit_radius", kDefaultHitRadius * double(std::max(sceneRadius, 1e-30f)), 1e-30, 1e30));
  out.hitEstimate.cacheStride = r.integer("hit_cache", kDefaultHitCacheStride, 0, 4096);
  out.nearLight = r.has("near_light") ? float(r.number("near_light", 0.0, 0.0, 1e30))
                                      : (out.hitGather && out.hitPhotons ? kNearLightAuto : 0.0f);
  if (out.nearLight > 0.0f && !(out.hitGather && out.hitPhotons))
    throw SettingsError("voxcone.near_light: needs gather = \"hit\" and hit_radiance = \"photons\"");
  const std::string edgeFit = r.choice("edge_fit", {"near", "all", "off"});
  out.nearEdgeFit = edgeFit != "off";
  out.hitEstimate.edgeFit = edgeFit == "all";
  const std::string view = r.choice("view", viewNames());
  out.view = View(std::find(viewNames().begin(), viewNames().end(), view) - viewNames().begin());
  r.finish();
  return out;
}

nlohmann::json VoxelConeSettings::toJson() const {
  return {{"max_depth", maxDepth},
          {"level", voxel.level},
          {"coarsest_level", voxel.coarsestLevel},
          {"caustic_level", voxel.causticLevel},
          {"kernel_sigma", voxel.kernelSigmaVoxels},
          {"mip_filter", mipFilterNames()[size_t(voxel.mipFilter)]},
          {"photons", photons.photons},
          {"photon_target", photonTarget},
          {"max_photons", maxPhotons},
          {"lamp_photons", lampPhotons},
          {"photon_guide", guideFloor},
          {"distant_aim", distantAim},
          {"caustic_photons", photons.causticPhotons},
          {"photon_seed", photons.seed},
          {"cones", cones},
          {"chain_cones", chainCones},
          {"glossy_cones", glossyCones},
          {"glossy_switch", glossySwitch},
          {"glint_samples", glintSamples},
          {"cone_angle", coneAngleDeg},
          {"cone_step", coneStep},
          {"max_distance", maxDistance},
          {"light_samples", lightSamples},
          {"hit_light_samples", hitLightSamples},
          {"gathers", gathers},
          {"filter", filterRadius},
          {"gather_spacing", gatherSpacing},
          {"filter_reach", filterReach},
          {"exact_segment", exactSegment},
          {"gather", hitGather ? "hit" : "march"},
          {"hit_radiance", hitPhotons ? "photons" : "field"},
          {"hit_direct", hitDirect ? "rays" : "photons"},
          {"hit_sky", hitSkyPhotons ? "photons" : "rays"},
          {"sky_light", skyByCones ? "cones" : "rays"},
          {"hit_photons", hitEstimate.k},
          {"hit_radius", hitEstimate.maxRadius},
          {"hit_cache", hitEstimate.cacheStride},
          {"near_light", nearLight == kNearLightAuto ? nlohmann::json("auto") : nlohmann::json(nearLight)},
          {"edge_fit", hitEstimate.edgeFit ? "all" : (nearEdgeFit ? "near" : "off")},
          {"view", viewNames()[size_t(view)]},
          {"field", fieldPath}};
}

}  // namespace voxcone

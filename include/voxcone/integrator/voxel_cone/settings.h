#pragma once
/// \file settings.h
/// voxcone's settings: what its options (`--options` JSON, voxel_cone.h lists them) set, with
/// their defaults, read and checked in one place (Tungsten's per-integrator settings struct).

#include "voxcone/photon/photon_radiance.h"
#include "voxcone/photon/photon_tracer.h"
#include "voxcone/scene/scene.h"
#include "voxcone/voxel/voxel_field.h"

#include <nlohmann/json.hpp>

#include <string>
#include <vector>

namespace voxcone {

/// Every option of the voxcone integrator, resolved (defaults applied, ranges checked).
struct VoxelConeSettings {
  /// One term of the image alone, for error studies (voxel_cone.h, `view`).
  enum class View { Full, Direct, Indirect, Caustic, Field };
  /// The `view` option's values, indexed by View.
  static const std::vector<std::string>& viewNames();
  /// The `mip_filter` option's values, indexed by MipFilter (the first is the default).
  static const std::vector<std::string>& mipFilterNames();

  int maxDepth = 16;            ///< longest specular chain (the render's max depth)
  VoxelSettings voxel;          ///< level, coarsest level, caustic level, photon footprint
  PhotonSettings photons;       ///< global and caustic photons, seed (render seed + `seed`)
  /// `photon_target`: with no photon count given (neither `photons` nor the scene's), the
  /// global photons are as many as put this many in the cells the camera's gathers read
  /// (SeenRegion): a pilot pass of photons.photons measures the share that lands there, and a
  /// second pass traces the count that share needs, up to `max_photons`. 0: photons.photons.
  uint64_t photonTarget = 0;
  uint64_t maxPhotons = 0;
  /// `lamp_photons` (with near_light): where the main pass sends fewer than a quarter of this
  /// many photons from the lamps (a sky or a sun takes the rest by power), a pass of the lamps'
  /// own photons makes them up to it for the near_light photons' estimates. Default the photon
  /// target (0 without one); 0: none.
  uint64_t lampPhotons = 0;
  /// `photon_guide`: with photon_target, the second pass's emission guided by where the pilot's
  /// photons were of use (EmissionGuide), each bin keeping `guideFloor` of its uniform share;
  /// 0: unguided.
  double guideFloor = 0.0;
  /// `distant_aim`: the share of a sun's or sky's photons emitted towards the sphere around most
  /// of what the camera's gathers read (PhotonSettings::distantTarget), the rest from the whole
  /// disc across the scene; 0: the whole disc alone.
  double distantAim = 0.5;
  int cones = 32;               ///< cones per gather, [1, 256] (default 32 with gather = "hit", 6 with "march")
  int chainCones = 8;           ///< cones per gather behind mirrors and glass (default 8 with "hit", `cones` with "march")
  int glossyCones = 4;          ///< most cones over one glossy lobe, [1, 64]
  float glossySwitch = 0.1f;    ///< roughness of a lobe one ray covers (fewer cones below: glossyLobeCones)
  /// `glint_samples`: samples per camera sample of the light seen through mirrors and glass, in
  /// the pixels that see them (Integrator::glintSamples); default 16 where the scene has a
  /// mirror or glass, else 0.
  int glintSamples = 0;
  double coneAngleDeg = 0.0;    ///< half-angle, degrees; 0: ConeSet's default for the count
  float coneStep = 1.0f;        ///< march step in lookup voxels, [0.25, 4]
  float maxDistance = 0.0f;     ///< world units; default the scene's bounding-sphere diameter
  int lightSamples = 1;         ///< shadow rays per shading point
  /// `hit_light_samples`: shadow rays to the lamps and suns at each cone's hit (with hit_direct =
  /// "rays"), spread over the light's samples by an R2 sequence around the cone's own; one where
  /// the only such light is a point light or a sun without extent (every ray would be the same).
  int hitLightSamples = 4;
  int gathers = 1;              ///< gathering samples per gathering pixel (0: every sample)
  int filterRadius = 12;        ///< screen-space filter radius, pixels (0: off)
  /// `filter_reach`: the filter carries a pixel's light at most this many times the distance from
  /// its point to the nearest other surface that meets its own (surfaceReach); 0: no limit.
  float filterReach = 1.0f;
  int gatherSpacing = 4;        ///< one gathering pixel per spacing x spacing block
  float exactSegment = 32.0f;   ///< exact ray along each cone axis, finest voxels (0: off)
  bool hitGather = true;        ///< gather = "hit" (the default) instead of "march"
  /// Where a cone's exact axis ray hits a diffuse surface, its radiance comes from the photons on
  /// that surface and side in sight of the hit (PhotonRadiance, `hit_radiance` = "photons", the
  /// default) or from the field's finest level around it ("field").
  bool hitPhotons = true;
  /// With hitPhotons: the direct light at a cone's hit by one shadow ray (`hit_direct` =
  /// "rays", the default), the photons then only the light that bounced ("photons": all of it
  /// from the photons).
  bool hitDirect = true;
  /// With hitDirect: the sky's light at a cone's hit from the photons straight from it
  /// (`hit_sky` = "photons", the default; PhotonRadianceSettings::skyDirect) or by a second
  /// shadow ray ("rays").
  bool hitSkyPhotons = true;
  /// The environment's light at diffuse shading points (`sky_light`): "cones" takes it from the
  /// gather's cones whose exact rays leave the scene (filtered with the indirect light; shadow
  /// rays leave the environment out), "rays" by shadow rays towards it as any light; "auto"
  /// (the default) cones under a constant sky, rays under a map.
  bool skyByCones = false;
  PhotonRadianceSettings hitEstimate;  ///< `hit_photons` (k), `hit_radius` (world units)
  /// `near_light` (world units; with gather = hit and hit_radiance = photons): the light leaving
  /// a surface point nearer than this to a lamp goes to the gathers partly by photons
  /// (LightProximity); 0: cones take all of it, a lamp nearer a cone's hit than a quarter of its
  /// width counting as that far; kNearLightAuto (the default): kNearLightScale times the mean
  /// distance a gather's rays travel (SeenRegion::meanGatherDistance), resolved in prepare().
  float nearLight = 0.0f;
  static constexpr float kNearLightAuto = -1.0f;
  /// `edge_fit`: where only part of an estimate's disc is its surface (an edge, a corner), the
  /// light at the point by a linear fit over that part (PhotonRadianceSettings::edgeFit) in the
  /// near_light photons' estimates ("near", the default), in those and the cones' hits ("all"),
  /// or in none ("off").
  bool nearEdgeFit = true;
  View view = View::Full;
  /// `field`: a .vdb written by `voxcone voxelize -o` (VoxelField::write) to render with instead
  /// of tracing photons and voxelizing; its settings (levels, footprint, mip filter, photons)
  /// are the field's, so those options may not be given with it.
  std::string fieldPath;

  /// Read `options` for `scene` rendered with `render` (whose photon counts and seed are the
  /// defaults' base); unknown keys and values out of range are SettingsErrors.
  static VoxelConeSettings fromOptions(const nlohmann::json& options, const Scene& scene, const RenderSettings& render);
  /// Every setting, as the options name them (cone_angle as given: 0 for the default).
  nlohmann::json toJson() const;
};

}  // namespace voxcone

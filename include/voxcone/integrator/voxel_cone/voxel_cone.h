#pragma once
/// \file voxel_cone.h
/// The voxcone method: exact hits from the HBVH for everything sharp, photon-injected voxels
/// gathered by cones for everything soft (Amanatides 1984 cones, Crassin et al. 2011 voxel cone
/// tracing, Jensen 2001 photon maps).
///
/// prepare(): photons are traced from the lights (global and, when a delta material exists,
/// caustic map), as many as put `photon_target` of them in the cells the camera's gathers read
/// (SeenRegion: a pilot pass of 10k, then the count its share needs; with `hit_direct` = "rays"
/// only photons that bounced count, being the ones the estimate uses; stats seen_photons; the
/// second pass guided, where that pays, by the pilot's useful photons: EmissionGuide), the
/// scene is voxelized at `level`, the photons are injected and the mips are built. With the
/// default `gather` = "hit" the global photons go into a kd-tree (PhotonRadiance) that cones
/// read at their exact hits, and the main grid holds only the caustic photons; with "march" it
/// holds all of them (and the caustic ones also go into a finer caustic grid).
///
/// li(): camera rays and specular chains are exact. At a delta surface every lobe is followed
/// (reflection and refraction, Fresnel-weighted; branches below 1e-3 of the pixel are cut) up
/// to max_depth. At a non-delta surface the reflected radiance is
///  - direct light: `light_samples` shadow rays to the lights (area lights sampled);
///  - diffuse surfaces: caustics from the caustic grid at the point, plus indirect light from
///    the cone set (cone_set.h) over the hemisphere on the viewer's side, each cone weighted by
///    f(wo, axis) * pi * w_i (albedo * w_i for Lambertian). By default ("hit") each cone is one
///    exact HBVH ray along its axis, the axes a stratified cosine-distributed set (a Hammersley
///    set shifted per gather through the cosine map, w_i = 1/N; the cone set turned about the
///    normal integrates at fixed elevations, gatherDiffuse), and the radiance at its hit is the
///    photons' estimate there
///    (PhotonRadiance: the k nearest photons on that surface, on the side the ray hit, in sight
///    of the hit): no voxel is shared with another surface, so no light crosses a wall. The
///    hit's direct light is one shadow ray (a light sample per cone, stratified over the
///    gather's cones), the photons only what bounced: photons straight from a light made the
///    sharpest part of the hit's light a blurred estimate (a knot's contact shadow on
///    small-objects came out lit; relMSE 0.00185 -> 0.00098);
///  - glossy surfaces (and a rough coat's glossy layer): n cones over strata of equal
///    probability of the lobe (a shifted Hammersley set through the BSDF's sampling map), each
///    weighted f cos / (n pdf), with n = ceil((roughness / glossy_switch)^2) up to
///    `glossy_cones`: one exact ray for a lobe at most glossy_switch rough. A cone's half-angle
///    is atan(roughness) (for the march). With gather = hit the lights the cones' axes meet
///    count too, and the glossy surface's light samples and they are weighted by the power
///    heuristic (multi-sample MIS). Caustics on a glossy surface (L S+ G: a light seen in a
///    mirror) come from the caustic pass's photons that ended there (PhotonMaps::glossyCaustic:
///    PhotonRadiance::reflected, its filtered estimate with each photon weighted by the BSDF,
///    on the gathering samples), or, without a caustic pass, from the cones through mirrors
///    and glass.
///
/// A cone of half-angle theta is marched front to back. Each sample is a filtered lookup whose
/// footprint has the variance of the cone's cross-section: directions uniform over the cone's
/// solid angle meet the plane at distance t with variance sigma^2 = t^2 (1 - cos theta) /
/// (2 cos theta) per axis (ConeTracer::crossSectionVariance; t^2 tan^2(theta) / 4 for narrow
/// cones, the disc's r^2 / 4), and a trilinear lookup in a mip of voxel size v has the variance
/// of the mips' prefilter plus the tent's v^2 / 6 (LookupFootprint: box mips v^2 / 4 in all,
/// v = 2 sigma; Gaussian mips, `mip_filter`, 5 v^2 / 12 - v0^2 / 6). Fractional levels blend two
/// mips. Along the axis the samples are spaced by
/// `cone_step` * v (1: the Gaussians' 2 sigma). A step meets a = dot(projected, |d|) * step / v0
/// surfaces (VoxelSample::projected; a plane adds up to exactly one crossing at every level), and
/// occlusion accumulates linearly, a' = min(a, 1 - A): C += a' L, A += a', with L the radiance of
/// the side of each surface that faces the cone's apex (ConeSample::radiance: surfaces are
/// two-sided and each side keeps its own light), until A > 0.99, the cone leaves the field or
/// max_distance. Linear accumulation keeps one wall exactly opaque (the furnace holds);
/// multiplicative compositing lets a wall split over two samples leak instead.
///
/// Self-occlusion: the shading point's own surface fills voxels whose centres lie within half
/// a voxel diagonal (sqrt(3)/2 v) of it, and a trilinear lookup takes the centres in the cube of
/// half-side v around it, which reaches up to sqrt(3) v along a tilted normal, so a lookup at
/// height h above the tangent plane is clear of the own surface when v <= h / (3 sqrt(3)/2)
/// (kClearance). The march follows the cone's own axis from the point, its first lookup where
/// the axis is 3 sqrt(3)/2 v0 above the tangent plane (v0: the finest voxel), and the lookup
/// size is min(v(sigma), h / (3 sqrt(3)/2)), snapped down to a whole level where the coarser mip
/// of a fractional level would not clear: a cone never sees its own tangent plane, without any
/// tuned offset. (Lifting the cone's origin off the surface instead shifts the cone towards
/// what it sees: an occluder 8 voxels away came out 30% too bright.) For all but the
/// narrowest cones the clearance, not the cone's width, sets the lookup size near the surface.
///
/// Light leaking: a wall thinner than a voxel shares voxels (radiance, occlusion) with the room
/// behind it. With `exact_segment` = S > 0 each cone first traces an exact HBVH ray along its
/// axis for S finest voxels; when that ray hits a surface the cone ends there, taking the
/// radiance at the hit from the finest level, half a voxel towards the ray's side. What is
/// left comes from coarse voxels that hold both rooms' walls: measured in the tests.
///
/// Options (unknown keys are SettingsErrors):
///  - `level` [1, 12] (default 5), `coarsest_level` [0, level] (default 1);
///  - `photons`, `caustic_photons`: fixed counts (default: the scene's render.photons /
///    caustic_photons; without either, `photon_target` decides the global count and the caustic
///    count is kVoxconeDefaultCausticPhotons (20k));
///  - `photon_target` (default 200000, 50000 under `render --denoise`; 0: off, then kVoxconeDefaultPhotons (10k)): global
///    photons wanted in the cells the camera's gathers read; `max_photons` (default 2M) caps the
///    count that takes (a scene whose seen part gets a tiny share of the light: the sidecar's
///    stats say what was seen: seen_cells, seen_photons);
///  - `caustic_level` (0: none; default level + 1 up to 12 when a delta material exists),
///    `kernel_sigma` (photon footprint, finest voxels, default 0.75), `seed` (added to the
///    render seed for the photon pass), `mip_filter` (`box`, default, or `gaussian`);
///  - `cones` [1, 256] (default 32 with gather = hit, 6 with march), `cone_angle` (half-angle
///    in degrees, default from the count: acos(1 - 1/N)), `cone_step` (0.25-4, default 1),
///    `max_distance` (world units, default: the scene's bounding-sphere diameter);
///  - `glossy_cones` [1, 64] (default 4), `glossy_switch` (roughness, default 0.1): cones over
///    a glossy lobe, as above;
///  - `chain_cones` [1, 256]: cones of a gather at a hit seen through mirrors and glass, which
///    cannot wait for the screen-space filter and gathers at every pixel (default 8 with gather
///    = hit, `cones` with march; the glass dragon took 13.6 s with 32);
///  - `hit_radiance`: what a hit cone reads at its hit: "photons" (default; PhotonRadiance) or
///    "field" (the field's voxels there at the cone's width: faster to build, but a voxel holds
///    both faces of a wall thinner than it, and light crosses: tests show it); `hit_photons`
///    (k, default 32), `hit_radius` (largest search radius, world units, default a tenth of the
///    scene's bounding radius), `hit_cache` (N > 1: the estimate precomputed at every N-th
///    photon from the others, and read from the nearest entry that passes the filters,
///    Christensen 1999: gathers 4x faster; default 8; 0 or 1: a full estimate at every hit),
///    `hit_direct` ("rays", default: the hit's direct light by a shadow ray, the photons only
///    what bounced; "photons": all of it from the photons); `near_light` (world units, default
///    a quarter of the mean distance a gather's rays travel, SeenRegion::meanGatherDistance;
///    0: off): a cone takes the share min(1, (d / near_light)^2)
///    of the light of a hit at distance d from the nearest lamp (LightProximity), and the photons
///    that left such surfaces (Photon::nearShare, those where the camera sees) carry the rest to
///    the gathering point, estimated there (gatherDiffuse); off, a lamp nearer a cone's hit than
///    a quarter of the cone's width counts as that far;
///  - `light_samples` (shadow rays per shading point, default 1);
///  - `gathers`: how many of a gathering pixel's samples gather indirect light by cones (default
///    1; 0: every one).
///    With spp > gathers, only samples 0 .. gathers-1 gather, weighted spp / gathers: the pixel's
///    expected value is unchanged, direct light, edges and specular chains keep every sample,
///    and the cones (98% of the time) cost gathers instead of spp. The stratified sampler gives
///    those samples' cone rotations and positions a stratified subset of the pixel;
///  - `filter`: radius in pixels of the screen-space filter of the cones' indirect light at
///    camera-visible diffuse surfaces (renderImage, filterIndirect; default 12, 0: off): each
///    pixel whose samples all saw one surface takes the Gaussian-weighted mean of its linked
///    neighbours' indirect light on the same material, normal and plane; a pixel whose samples
///    saw several surfaces takes, per sample, the filtered light of a filter pixel nearby on that
///    sample's surface (or gathers itself where there is none);
///  - `gather_spacing` [1, 16] (default 4 with the filter, 1 without; above 1 only with it): one
///    pixel per spacing x spacing block gathers (the cones wait until every pixel's samples are
///    taken, liSplit's DeferredGather); the filter fills the others, and any pixel it cannot
///    fill gathers itself;
///  - `exact_segment` (finest voxels, 0 = off, default 32);
///  - `gather`: "hit" (default): one exact HBVH ray per cone axis, the radiance at its hit as
///    `hit_radiance` says (a cone whose axis misses a surface counts none of it, one that hits
///    counts all of it: 32 cones make that noise small); or "march", the cone marching above
///    through the mips (6 cones; its light leaks through walls thinner than a voxel beyond the
///    exact segment);
///  - `view`: "full" (default), or one term alone for error studies: "direct" (emission and
///    shadow rays), "indirect" (cones), "caustic" (caustic grid), "field" (the main grid's
///    radiance at the first non-delta hit: what cones see there);
///  - `field`: a .vdb from `voxcone voxelize -o` to render with instead of tracing photons and
///    voxelizing (VoxelField::read; it fixes level, coarsest_level, caustic_level,
///    kernel_sigma, mip_filter and the photons, which may not be given with it) a field read back
///    has no photons, so its hit cones read the field: hit_radiance = field);
///  - `memory_budget_mb`: refuse a level whose estimated memory exceeds it (default the
///    machine's available memory, 0 none; VoxelSettings::memoryBudgetBytes).
/// Deterministic: the photon pass and the field are identical at any thread count, and li()
/// draws only from the pixel's stream.

#include "voxcone/integrator/integrator.h"
#include "voxcone/integrator/voxel_cone/cone_set.h"
#include "voxcone/integrator/voxel_cone/cone_tracer.h"
#include "voxcone/integrator/voxel_cone/screen_space_gather.h"
#include "voxcone/integrator/voxel_cone/settings.h"
#include "voxcone/voxel/voxel_field.h"

#include <memory>
#include <optional>

namespace voxcone {

class LightProximity;

class VoxelConeIntegrator final : public Integrator, public ScreenSpaceGather {
public:
  explicit VoxelConeIntegrator(const IntegratorContext& context);
  std::string name() const override { return "voxcone"; }
  void prepare(Progress* progress) override;
  /// prepare() again with photons of another seed (what the passes of a progressive render
  /// differ in): without a caustic grid the voxelization is kept and only the photons are
  /// traced and injected again (it depends on the geometry alone); with one, everything is
  /// rebuilt (the caustic grid holds only voxels near its photons).
  void reseed(uint64_t photonSeed, Progress* progress);
  const VoxelConeSettings& settings() const { return m_settings; }
  Vec3 li(const Ray& ray, Sampler& sampler) const override;
  const ScreenSpaceGather* screenSpaceGather() const override { return this; }
  int indirectFilterRadius() const override { return m_settings.filterRadius; }
  Vec3 liSplit(const Ray& ray, Sampler& sampler, IndirectSplit& split) const override;
  bool separatesTerms() const override { return true; }
  Vec3 liTerms(const Ray& ray, Sampler& sampler, IndirectSplit* split, RadianceTerms& terms) const override;
  Vec3 gatherDeferred(const DeferredGather& gather) const override;
  int gatherSpacing() const override { return m_settings.gatherSpacing; }
  /// Adjacent pixels on one surface are linked when an exact ray between their points, a
  /// quarter of a footprint above the surface, meets nothing.
  void linkIndirect(IndirectBuffer& buffer) const override;
  bool linkedPoints(const Vec3& from, const Vec3& to) const override;
  int glintSamples() const override { return m_settings.glintSamples; }
  bool glintsVary(const Ray* probes, int count) const override;
  Vec3 liGlint(const Ray& ray, Sampler& sampler) const override;
  nlohmann::json settingsJson() const override;
  nlohmann::json statsJson() const override;

private:
  using View = VoxelConeSettings::View;
  /// The cones' indirect light at a diffuse hit seen from woWorld, the cone set turned by 2 pi u
  /// (the chain's set, `chain_cones`, at a hit behind mirrors and glass).
  /// `untextured`: a textured albedo taken as 1 (IndirectSplit::albedo multiplies it back).
  Vec3 gatherDiffuse(const SurfaceHit& sh, const Vec3& woWorld, float u, bool chain = false, bool untextured = false) const;
  /// The light a glossy lobe gathers at sh (a rough conductor's or dielectric's, or with `coat`
  /// a rough coat's alone): glossyLobeCones(roughness) cones over strata of the lobe. With
  /// `emission` (gather = hit), the emission the cones' axes find there, MIS-weighted against
  /// the light samples (misWeightedEmission); with `caustic` (gather = hit), the light they find
  /// through mirrors and glass (ConeTracer::trace's deltaLight).
  Vec3 gatherLobe(const SurfaceHit& sh, const Frame& frame, const Vec3& wo, const Material& mat, Sampler& sampler,
                  bool coat, Vec3* emission, Vec3* caustic) const;
  /// Cones over a lobe of this roughness: ceil((roughness / glossy_switch)^2), 1 to glossy_cones.
  int glossyLobeCones(float roughness) const;
  /// Reflected radiance at a non-delta hit; with `split`, the cones' indirect light of a diffuse
  /// hit goes there instead (with the hit's position, normal and material). With `terms`, its
  /// direct, caustic and indirect parts are added there, times `weight` (the delta chain's);
  /// `depth`: the delta bounces before this hit.
  Vec3 shade(const SurfaceHit& sh, const Vec3& woWorld, Sampler& sampler, IndirectSplit* split, RadianceTerms* terms,
             const Vec3& weight, int depth) const;
  /// The photon maps: settings.photons photons, or with a photon target as many as put that
  /// many in the cells the camera's gathers read (a pilot pass, then the count its share
  /// needs). Starts m_stats with the seen cells and photons.
  PhotonMaps tracePhotonsForView(Progress* progress);
  /// The photons that left surfaces beside the lamps, where the camera sees, each with its near
  /// share of its power (m_nearPhotons' photons).
  std::vector<Photon> nearPhotons(const PhotonMaps& maps) const;
  /// With near_light, where the main pass (`emitted` photons) sent fewer than lamp_photons /
  /// kNearLampStarved from the lamps (a sky or a sun took them by power): the near photons of a
  /// pass of the lamps' own photons join `near`, each pass's weighted by its share.
  void addLampPass(std::vector<Photon>& near, uint64_t emitted, Progress* progress);
  /// Trace the photons, voxelize unless `keepVoxels` (and a field exists), inject, build mips.
  void build(bool keepVoxels, Progress* progress);
  /// The cone tracer over the field just built or read, and the caustic voxel size.
  void startTracer();
  /// li, with the first hit's indirect light in `split` when it is given and the terms in
  /// `terms` when that is.
  Vec3 trace(const Ray& ray, Sampler& sampler, IndirectSplit* split, RadianceTerms* terms) const;

  const Scene& m_scene;
  const Accel& m_accel;
  VoxelConeSettings m_settings;
  ConeSet m_cones;
  float m_tanHalf = 0.0f;       ///< tan of the cones' half-angle
  ConeSet m_chainCones;         ///< gathers behind mirrors and glass (chain_cones)
  float m_chainTanHalf = 0.0f;

  VoxelField m_field;
  PhotonRadiance m_hitPhotons;  ///< the photons' estimate at cones' exact hits (hit_radiance)
  /// How near surfaces are to the lamps (near_light), and the photons that left surfaces beside
  /// them, each with its near share of its power: the light the cones leave to the gathering
  /// point's own estimate.
  std::shared_ptr<const LightProximity> m_proximity;
  PhotonRadiance m_nearPhotons;
  PhotonRadiance m_glossyCaustics;  ///< over the caustic photons on glossy surfaces (PhotonMaps::glossyCaustic)
  bool m_glossyCausticByPhotons = false;  ///< L S+ G from those photons (else from the cones, trace's deltaLight)
  std::optional<ConeTracer> m_tracer;  ///< once prepare() built the field
  float m_causticVoxel = 0.0f;  ///< caustic grid voxel size (the finest voxel without one)
  nlohmann::json m_stats = nlohmann::json::object();
};

}  // namespace voxcone

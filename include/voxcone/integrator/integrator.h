#pragma once
/// \file integrator.h
/// The integrator interface, the registry of integrators by name (Tungsten's
/// IntegratorFactory), and the tile-parallel render driver.

#include "voxcone/core/progress.h"
#include "voxcone/core/sampler.h"
#include "voxcone/image/image.h"
#include "voxcone/scene/scene.h"

#include <nlohmann/json.hpp>

#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace voxcone {

class Accel;
class ScreenSpaceGather;
struct IndirectSplit;

/// What a camera sample's radiance is made of (the term AOVs), each term weighted by the
/// throughput of the delta (mirror, glass) chain that reached it, so that emitted + direct +
/// caustic + indirect is the sample's radiance. At the first non-delta surface of each chain:
/// emitted: light sources seen from the camera, directly or through delta bounces (E S* L);
/// direct: light arriving there straight from a light (E S* D L); caustic: light arriving
/// there from a light through delta bounces (E S* D S+ L; voxcone: its caustic photons);
/// indirect: everything else (voxcone: the cones).
struct RadianceTerms {
  Vec3 emitted{0.0f}, direct{0.0f}, caustic{0.0f}, indirect{0.0f};
  /// The part of `emitted` seen after one or more mirror or glass bounces (a light's glints).
  Vec3 glint{0.0f};
};

/// Estimates the radiance arriving along camera rays. Implementations are immutable while
/// rendering (`li` is called concurrently); per-render work happens in `prepare`.
class Integrator {
public:
  virtual ~Integrator() = default;
  /// Registered name ("path", "whitted", ...).
  virtual std::string name() const = 0;
  /// One-time work before rendering (photon tracing, voxelization in later parts).
  virtual void prepare(Progress* progress) {}
  /// Radiance along `ray` (a camera ray); `sampler` is this pixel's sample source, at the
  /// current sample (core/sampler.h).
  virtual Vec3 li(const Ray& ray, Sampler& sampler) const = 0;
  /// The screen-space gather protocol renderImage follows where the integrator has one
  /// (voxcone: integrator/voxel_cone/screen_space_gather.h): deferred gathers at some pixels and
  /// a filter of their indirect light; none (null) renders every sample whole.
  virtual const ScreenSpaceGather* screenSpaceGather() const { return nullptr; }
  /// Whether liTerms separates this integrator's terms (RadianceTerms).
  virtual bool separatesTerms() const { return false; }
  /// li (split null) or ScreenSpaceGather::liSplit (split given), the same estimate from the
  /// same samples, with its terms added to `terms` (what liSplit splits off stays out of both).
  /// Throws Error unless separatesTerms().
  virtual Vec3 liTerms(const Ray& ray, Sampler& sampler, IndirectSplit* split, RadianceTerms& terms) const;
  /// Extra samples, per camera sample, of the light seen through mirrors and glass (0: none).
  /// renderImage takes them in the pixels where glintsVary says so for the pixel's fixed probe
  /// rays, and in their neighbours, from a sampler of their own, and there counts the glints
  /// (RadianceTerms::glint) from them instead of from the camera samples: a light's image in
  /// glass is a small, bright target whose pixel integral is most of such a pixel's noise, and
  /// costs only the rays of its delta chains.
  virtual int glintSamples() const { return 0; }
  /// Whether the light seen through mirrors and glass may vary over a pixel whose probe rays
  /// (fixed rays through it) are `probes`.
  virtual bool glintsVary(const Ray* probes, int count) const { return false; }
  /// The light seen along `ray` after one or more delta bounces, nothing else (RadianceTerms::glint).
  virtual Vec3 liGlint(const Ray& ray, Sampler& sampler) const { return Vec3(0.0f); }
  /// Settings as JSON (written into sidecars).
  virtual nlohmann::json settingsJson() const { return nlohmann::json::object(); }
  /// Statistics gathered in prepare/li, as JSON.
  virtual nlohmann::json statsJson() const { return nlohmann::json::object(); }
};

/// What an integrator is built from. `options` are integrator-specific settings; every key an
/// integrator does not read is an error (unused settings are reported, as pbrt-v4 does).
struct IntegratorContext {
  const Scene& scene;
  const Accel& accel;
  RenderSettings settings;
  nlohmann::json options = nlohmann::json::object();
};

using IntegratorFactory = std::function<std::unique_ptr<Integrator>(const IntegratorContext&)>;

/// Register a factory under `name` (called from each integrator's translation unit through
/// the table in registry.cpp).
void registerIntegrator(const std::string& name, IntegratorFactory factory);
/// Create the integrator `name`; throws SettingsError for an unknown name or bad options.
std::unique_ptr<Integrator> createIntegrator(const std::string& name, const IntegratorContext& context);
/// The registered names, sorted.
std::vector<std::string> integratorNames();

/// Layers a render can write beside the beauty image (--aov), pbrt-v4's G-buffer names where
/// it has them. albedo, normal, depth: the camera ray's first hit, box-filtered like the beauty
/// (each pixel the mean over its samples; a sample that hits nothing adds 0): Albedo.RGB the
/// material's diffuse albedo (its specular tint for mirrors, metals and glass, as denoisers
/// take it), Ns.XYZ the unit shading normal turned to the viewer, world space, Z the distance
/// along the camera's viewing axis. The terms (RadianceTerms): Emitted, Direct, Caustic,
/// Indirect, each .RGB; with the indirect filter, Indirect holds the filtered light.
enum class Aov { Albedo, Normal, Depth, Emitted, Direct, Indirect, Caustic };
/// The names --aov takes, in Aov order.
const std::vector<std::string>& aovNames();
/// A comma-separated list of aovNames() (no repeats), in the order given. Throws SettingsError.
std::vector<Aov> parseAovs(const std::string& list);
/// The layer's EXR channel names.
std::vector<std::string> aovChannels(Aov aov);
/// Whether the layer is one of the terms (needs Integrator::separatesTerms).
bool isTermAov(Aov aov);
/// Throws SettingsError naming the first term layer of `layers` that `integrator` cannot
/// separate (renderImage checks it; the CLI calls it before the integrator's prepare).
void checkAovs(const Integrator& integrator, const std::vector<Aov>& layers);

/// AOVs renderImage computes beside the beauty; `accel` finds the first hits.
struct AovRequest {
  std::vector<Aov> layers;
  const Accel* accel = nullptr;
};

/// Output of render().
struct RenderResult {
  Image image;
  double seconds = 0.0;       ///< wall time of the pixel loop
  uint64_t samples = 0;       ///< camera samples taken
  uint64_t invalidSamples = 0;///< NaN/inf estimates dropped (should be 0)
  /// Seconds per stage of the pixel loop: "samples" (every pixel's samples), and with the
  /// indirect filter "link", "gather" (the deferred gathers) and "filter".
  nlohmann::json stageSeconds = nlohmann::json::object();
  /// With the indirect filter: pixels the filter takes ("filterable"), pixels that ran their
  /// deferred gathers ("gathering"; "unfilled": those only because no neighbour gathers), and
  /// the gathers run ("gathers").
  nlohmann::json filterStats = nlohmann::json::object();
  std::vector<ImageLayer> layers;  ///< the AOVs asked for, in the order asked
  int completedSpp = 0;   ///< samples per pixel in the image (below settings.spp when partial)
  bool partial = false;   ///< interrupted: the image holds the passes that completed
};

/// Render with tiles of 16x16 pixels in parallel (TBB). Pixel (x, y) draws its samples from
/// Sampler(settings.sampler, settings.seed, y * width + x), sample s starting at dimension 0,
/// its first slot the jitter, so the image is bit-identical at any thread count.
/// Box pixel filter: each sample is uniform in the pixel's square. For an integrator with a
/// screen-space gather (Integrator::screenSpaceGather) of indirect filter radius > 0, each pixel's
/// indirect light (ScreenSpaceGather::liSplit) is replaced by its neighbours' weighted mean where
/// all its samples saw one surface (filterIndirect, deterministic). A pixel whose samples saw
/// several surfaces (an edge) takes, per sample, the filtered light of the nearest filter pixel
/// within 2 pixels on that sample's surface that its point sees (ScreenSpaceGather::linkedPoints),
/// when every one of its samples finds one. Deferred gathers (IndirectSplit::deferred) run after
/// every pixel's samples, at one pixel per ScreenSpaceGather::gatherSpacing() block (chosen per
/// block from the seed), at every edge pixel that cannot take its light that way, and at every
/// pixel with no gathering pixel among its filter neighbours; the filter then fills the others from
/// their neighbours.
/// Without the indirect filter the samples are taken in passes over all pixels (1, 1, 2, 4, ...
/// up to 64 samples each; the image is the same bit for bit): cancellation is seen within a
/// fraction of a second at any spp, and with `keepPartial` the render then returns the passes
/// that completed (RenderResult::partial, completedSpp) instead of throwing. Otherwise (and
/// with the filter, whose samples are one pass) cancellation throws CancelledError.
/// With `aovs`, each sample is taken through liTerms (the same image) and the layers asked for
/// are returned in RenderResult::layers; term layers need Integrator::separatesTerms (else
/// SettingsError).
RenderResult renderImage(const Scene& scene, const Integrator& integrator, const RenderSettings& settings,
                         Progress* progress = nullptr, bool keepPartial = false, const AovRequest* aovs = nullptr);

/// Samples of `integrator`'s li at `pixels` (indices y * width + x): `settings.spp` each, drawn
/// as renderImage draws them (the same sampler, seed and jitter), no indirect filter; their sum
/// and sum of squares per channel (samples renderImage would drop, non-finite or negative, not counted). Parallel,
/// deterministic.
struct PixelSamples {
  DVec3 sum{0.0}, sumSquares{0.0};
  uint32_t count = 0;
};
std::vector<PixelSamples> renderPixels(const Scene& scene, const Integrator& integrator, const RenderSettings& settings,
                                       const std::vector<size_t>& pixels);

}  // namespace voxcone

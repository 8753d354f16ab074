#pragma once
/// \file photon_tracer.h
/// Photon tracing from the lights (Jensen 2001, "Realistic Image Synthesis Using Photon
/// Mapping", ch. 5): photons leave the lights in proportion to power, follow exact specular
/// reflection/refraction through the HBVH, are stored at diffuse hits and survive diffuse
/// bounces by Russian roulette on the albedo.

#include "voxcone/core/bounds.h"
#include "voxcone/core/math.h"
#include "voxcone/core/progress.h"
#include "voxcone/photon/emission_guide.h"

#include <nlohmann/json_fwd.hpp>

#include <cstdint>
#include <memory>
#include <vector>

namespace voxcone {

class Scene;
class Accel;
class LightProximity;

/// A photon stored at a diffuse surface hit.
struct Photon {
  Vec3 position{0.0f};   ///< world space
  Vec3 power{0.0f};      ///< flux carried, W per RGB channel
  Vec3 incident{0.0f};   ///< unit direction towards where the photon came from (away from the surface)
  Vec3 normal{0.0f};     ///< unit shading normal, flipped to the side the photon arrived on
  /// Diffuse reflectance of the surface it landed on: the voxel field injects the reflected
  /// power (power * albedo), so it stores no albedo of its own.
  Vec3 albedo{0.0f};
  /// Scattering events between the light and this hit, saturating at 255: 0 for a photon
  /// straight from a light (direct light, which photon mapping takes from shadow rays).
  uint8_t bounces = 0;
  /// 1 for a photon that left the environment (the sky), else 0.
  uint8_t fromEnvironment = 0;
  /// With PhotonSettings::proximity: 1 - coneShare of the last diffuse surface it left (the
  /// share of the light leaving there that cones leave to photons, LightProximity), else 0.
  float nearShare = 0.0f;
};

/// voxcone's photons when the scene names none. Measured with voxcone's defaults (256x256,
/// 4 spp, 2 threads, against path at 4096 spp): cornell-box 35.68 / 35.82 / 35.86 / 35.88 dB at
/// 5k / 7.5k / 10k / 15k photons, cornell-dragon 35.37 / 35.57 / 35.69 / 35.90 dB, while
/// prepare takes 0.10 / 0.11 / 0.12 / 0.12 s on the dragon. (At 16 spp and 4 gathers, where the
/// cones' own noise is lower, 100k gave 0.1 dB less than 1M; the filter now averages that out.)
constexpr uint64_t kVoxconeDefaultPhotons = 10000;
/// Its caustic photons when the scene names none: cornell-dragon-glass (3 spp, defaults)
/// 28.81 / 30.02 / 30.12 / 30.24 dB at 2k / 20k / 40k / 80k emitted (prepare 0.17 / 0.18 / 0.19
/// / 0.21 s): only the few that pass the glass are stored (623 of 20k).
constexpr uint64_t kVoxconeDefaultCausticPhotons = 20000;
/// Photon mapping's photons when the scene names none: its k-NN estimate needs many more
/// (cornell-box, 16 spp: 34.8 dB at 100k, 36.2 dB at 1M).
constexpr uint64_t kPhotonMappingDefaultPhotons = 1000000;

/// The photon counts a method uses: the scene's (`scenePhotons`, `sceneCaustic`; 0 = not given)
/// or its own defaults; without a caustic default (0) the caustic map is a fifth of the global
/// one unless given.
inline void defaultPhotonCounts(uint64_t scenePhotons, uint64_t sceneCaustic, uint64_t methodDefault,
                                uint64_t methodCausticDefault, uint64_t& photons, uint64_t& causticPhotons) {
  photons = scenePhotons > 0 ? scenePhotons : methodDefault;
  causticPhotons = sceneCaustic > 0 ? sceneCaustic : methodCausticDefault > 0 ? methodCausticDefault : photons / 5;
}

/// Photon tracing settings.
struct PhotonSettings {
  uint64_t photons = 200000;        ///< photons emitted for the global map
  uint64_t causticPhotons = 100000; ///< photons emitted for the caustic map (0: none)
  int maxDepth = 16;                ///< longest photon path (segments)
  uint64_t seed = 0;                ///< photon i of pass p uses the stream (seed, p * 2^40 + i)
  /// Caustic photons leave the lights only towards the bounding sphere of the specular (delta)
  /// triangles, weighted by that cone's solid angle (Jensen's projection maps, with a sphere for
  /// the map): an L S+ D path must meet a specular surface first, so nothing is lost, and far
  /// more of the pass's photons become caustics.
  bool aimCaustics = true;
  /// The global pass's emission through this guide (EmissionGuide: photons guided to what the
  /// camera sees, weighted so that the map stays unbiased); none: unguided.
  std::shared_ptr<const EmissionGuide> guide;
  /// PhotonMaps::globalSamples names the emission (after the guide's remapping) of each global photon.
  bool recordSamples = false;
  /// Where given, each global photon records the near share of the last diffuse surface it left
  /// (Photon::nearShare).
  std::shared_ptr<const LightProximity> proximity;
  /// Distant lights (directional, environment) emit `distantShare` of their photons towards this
  /// sphere (LightEmission::setDistantTarget); radius < 0: from the whole disc alone.
  Sphere distantTarget;
  double distantShare = 0.0;
  /// The lamps alone emit (emissive triangles and point lights), by their power among themselves.
  bool localOnly = false;
};

/// The share of a pass's photons that leave lamps (emissive triangles and point lights), not the
/// sky or a sun: their share of the power the lights are chosen by.
double lampPhotonShare(const Scene& scene);

/// The values of a photon's uLight where the choice of one light ends and the next begins
/// (EmissionGuide::fromUseful's light edges).
std::vector<double> lightChoiceEdges(const Scene& scene);

/// Statistics of one tracing run.
struct PhotonStats {
  uint64_t emittedGlobal = 0, emittedCaustic = 0;
  uint64_t storedGlobal = 0, storedCaustic = 0, storedGlossyCaustic = 0;
  Vec3 emittedPower{0.0f};   ///< total light flux (W per channel) every pass distributes
  double seconds = 0.0;
  nlohmann::json toJson() const;
};

/// The two photon maps: caustic photons arrived by light paths L S+ D (one or more specular
/// bounces straight from a light), global photons are every other diffuse hit (direct light
/// included). Each pass carries the lights' full flux: the global map alone is an unbiased
/// estimate of everything but caustics, the caustic map of caustics alone.
struct PhotonMaps {
  std::vector<Photon> global;
  std::vector<Photon> caustic;
  /// The caustic pass's photons that arrived at a glossy surface (rough conductor, rough
  /// dielectric) after specular bounces only, L S+ G: their first glossy hit, where the path
  /// ends (albedo 0: the glossy surface's BSDF weighs them where it is shaded).
  std::vector<Photon> glossyCaustic;
  /// With PhotonSettings::recordSamples: the primary sample each global photon was emitted from.
  std::vector<EmissionSample> globalSamples;
  PhotonStats stats;
};

/// Trace both passes in parallel (TBB). Photon i's random stream depends only on (seed, pass,
/// i) and photons are stored in index order, so the maps are identical at any thread count.
/// Throws CancelledError when `progress` cancels.
PhotonMaps tracePhotons(const Scene& scene, const Accel& accel, const PhotonSettings& settings,
                        Progress* progress = nullptr);

}  // namespace voxcone

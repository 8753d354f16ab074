#pragma once
/// \file scene.h
/// The immutable scene: world-space triangles, materials, lights, camera and render settings.
/// It knows nothing of accelerators (accel/ builds those from it).

#include "voxcone/core/bounds.h"
#include "voxcone/core/ray.h"
#include "voxcone/core/sampler.h"
#include "voxcone/scene/camera.h"
#include "voxcone/scene/environment.h"
#include "voxcone/scene/light_tree.h"
#include "voxcone/scene/material.h"
#include "voxcone/scene/texture.h"

#include <nlohmann/json_fwd.hpp>

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace voxcone {

/// A point light: radiant intensity in W/sr per channel.
struct PointLight {
  Vec3 position{0.0f};
  Vec3 intensity{0.0f};
};

/// A distant light (the sun): rays along `direction`, irradiance `irradiance` (W/m^2 per
/// channel) on a surface facing them. A delta light when cosHalfAngle is 1; else a disc of
/// uniform radiance L = E / (pi sin^2 theta) seen within half-angle theta of -direction
/// (`angle_deg` the full angle: the sun's is 0.53), sampled uniformly in that cone and seen by
/// rays that leave the scene inside it. Its flux, for choosing lights and emitting photons, is
/// what crosses the scene's bounding sphere: irradiance * pi R^2 (pbrt-v4's DistantLight::Phi).
struct DirectionalLight {
  Vec3 direction{0.0f, -1.0f, 0.0f};  ///< unit, the direction the light travels
  Vec3 irradiance{0.0f};
  float halfAngle = 0.0f;             ///< theta, radians; 0: a delta light

  bool isDelta() const { return !(halfAngle > 0.0f); }
  float cosHalfAngle() const { return std::cos(halfAngle); }
  /// 1 - cos theta, without cancellation (2 sin^2 (theta / 2)).
  float oneMinusCos() const { return 2.0f * sqr(std::sin(0.5f * halfAngle)); }
  /// The disc's radiance (finite suns): E / (pi sin^2 theta).
  Vec3 radiance() const { return irradiance / (kPi * sqr(std::sin(halfAngle))); }
  /// The uniform cone's solid angle, 2 pi (1 - cos theta).
  float solidAngle() const { return 2.0f * kPi * oneMinusCos(); }
  /// Whether a ray leaving the scene along `dir` (unit) sees the disc.
  bool seenAlong(const Vec3& dir) const { return !isDelta() && 1.0f + glm::dot(dir, direction) <= oneMinusCos(); }
};

/// Settings a scene file may give and the command line may override.
struct RenderSettings {
  int width = 256;
  int height = 256;
  int spp = 16;            ///< samples per pixel, >= 1
  int maxDepth = 16;       ///< longest path (number of segments) for path / recursion for whitted
  uint64_t seed = 0;
  SamplerKind sampler = SamplerKind::Sobol;  ///< how pixels draw their samples (core/sampler.h)
  std::string method = "voxcone";
  /// Photons emitted for the global map; 0: the method's own default (voxcone
  /// kVoxconeDefaultPhotons, pm kPhotonMappingDefaultPhotons).
  uint64_t photons = 0;
  /// Photons emitted for the caustic map, when caustics are possible; 0: the method's default
  /// (voxcone kVoxconeDefaultCausticPhotons, pm a fifth of the global map's).
  uint64_t causticPhotons = 0;
  /// How lights are chosen for a shading point: by a light tree (their estimated contribution
  /// there, the default) or in proportion to their power alone ("power", for comparisons).
  bool lightTree = true;
  /// The light tree's split angle in degrees (LightTree::sampleSplit; 0: one light per sample).
  /// Measured on many-lights (256x256, 16 spp, 2 threads, against path at 4096 spp), splitting
  /// to depth 4 (up to 16 light samples): path 26.1 dB in 1.8 s without, 29.3 / 29.7 / 30.2 dB
  /// in 2.95 / 3.19 / 3.60 s at 75 / 60 / 45 degrees (depth 3 at 45: 29.5 dB in 3.5 s; depth 5:
  /// 30.3 dB in 4.0 s); voxcone 31.3 dB in 1.35 s without, 37.2 / 38.0 / 39.3 dB in 1.33 / 1.39
  /// / 1.52 s at 75 / 60 / 45 degrees. Path without splitting reaches 30.2 dB at about 38 spp,
  /// 4.2 s (between its 26.1 dB at 16 spp and 32.7 dB at 64 spp, 6.6 s).
  float lightSplitDeg = 45.0f;
  /// The image goes through the denoiser (`render --denoise`): methods may choose cheaper
  /// defaults whose noise it removes (voxcone's photon_target, voxel_cone/settings.cpp).
  bool denoise = false;
  /// Throws SettingsError naming the offending value.
  void validate() const;
};

/// A named group of triangles as given in the scene file (a quad or a mesh).
struct ShapeInfo {
  std::string name;
  uint32_t firstTriangle = 0;
  uint32_t triangleCount = 0;
  bool smoothNormals = false;
  bool hasUvs = false;  ///< its vertices carry texture coordinates
};

/// A light sample towards a shading point.
struct LightSample {
  Vec3 radiance{0.0f};   ///< Le (area, environment), I/r^2 (point) or E (directional) arriving along -wi, before visibility
  Vec3 wi{0.0f};         ///< unit direction from the shading point to the light
  Vec3 lightPos{0.0f};   ///< sampled point on the light
  Vec3 lightPosError{0.0f};///< bound on lightPos's rounding error per axis (zero for point lights)
  Vec3 lightNormal{0.0f};///< geometric normal there (zero for point lights)
  float distance = 0.0f; ///< to lightPos (a directional or environment light's: beyond the scene's bounds)
  float pdf = 0.0f;      ///< solid-angle pdf (including the light choice); 0 = failed
  bool delta = false;    ///< point or directional light (cannot be hit by BSDF sampling)
};

/// The surface at a ray hit.
struct SurfaceHit {
  Vec3 position{0.0f};     ///< from the hit's barycentrics (not origin + t dir)
  Vec3 positionError{0.0f};///< bound on position's rounding error per axis (barycentricPoint)
  Vec3 geomNormal{0.0f};   ///< unit, from the winding: normalize(cross(v1-v0, v2-v0))
  Vec3 shadingNormal{0.0f};///< unit; the geometric one for flat shading
  Vec2 uv{0.0f};           ///< texture coordinates (Scene::uvs interpolated), (0, 0) without
  uint32_t triangle = 0;
  uint32_t material = 0;
};

/// World-space scene. Built by the loaders; immutable afterwards.
class Scene {
public:
  // Geometry, flattened over all shapes.
  std::vector<Vec3> positions;
  std::vector<Vec3> normals;           ///< per vertex, or empty when no shape is smooth
  std::vector<Vec2> uvs;               ///< per vertex texture coordinates, or empty when no shape has them
  std::vector<UVec3> triangles;
  std::vector<uint32_t> triMaterial;   ///< per triangle index into materials
  std::vector<uint32_t> triShape;      ///< per triangle index into shapes
  std::vector<ShapeInfo> shapes;
  std::vector<Material> materials;
  std::vector<std::shared_ptr<const Texture>> textures;  ///< what materials' albedoTexture index
  std::vector<PointLight> pointLights;
  std::vector<DirectionalLight> directionalLights;
  /// The sky: radiance arriving from infinity along rays that leave the scene; null for none.
  std::shared_ptr<const Environment> environment;
  Camera camera;
  RenderSettings render;
  std::string sourcePath;              ///< file the scene came from (for messages and sidecars)
  /// Every file the scene was read from, in load order: the scene file itself (when it came from
  /// one), then each mesh (sidecars record their content hashes).
  std::vector<std::string> inputFiles;

  /// Precompute the light distribution and bounds; call once after filling the fields.
  void finalize();

  size_t triangleCount() const { return triangles.size(); }
  const Bounds3& bounds() const { return m_bounds; }
  /// Bounding sphere of the scene bounds.
  Sphere boundingSphere() const;

  /// Surface data at barycentrics (b1, b2) of `triangle`: the point itself is interpolated
  /// from the vertices, with its error bound, because origin + t dir carries the error of t
  /// times the ray's length (the bias of every shadow ray from surfaces near coordinate 0).
  SurfaceHit surfaceAt(uint32_t triangle, float b1, float b2) const;

  /// The material at a hit: its own, or with a texture its albedo there (the texture times the
  /// material's factor, clamped to [0, 1]) in `scratch`, which is returned.
  const Material& materialAt(const SurfaceHit& hit, Material& scratch) const {
    const Material& m = materials[hit.material];
    if (m.albedoTexture < 0) return m;
    static_cast<MaterialParams&>(scratch) = m;
    scratch.albedo = glm::clamp(m.albedo * textures[size_t(m.albedoTexture)]->lookup(hit.uv), Vec3(0.0f), Vec3(1.0f));
    return scratch;
  }

  /// Emitted radiance leaving an emissive surface towards direction `w` (unit, pointing away).
  Vec3 emitted(const SurfaceHit& hit, const Vec3& w) const;

  // Lights. Every emissive triangle, point light and directional light, and the environment,
  // is one light. The lights at infinity (directional, environment) are chosen in proportion to
  // their power (luminance of emitted flux; the environment's pi R^2 times its radiance's
  // integral over the sphere, R the bounding sphere's), and so is the set of bounded lights
  // (emissive triangles, point lights) as a whole; within that set a light tree (light_tree.h)
  // chooses one by its estimated contribution at the shading point, or, with
  // render.lightTree false, again in proportion to power.
  size_t lightCount() const { return m_lightCount; }
  bool hasLights() const { return m_lightCount > 0; }
  /// Sample a light towards `ref` with one 2D sample u: u.x chooses the light, then, rescaled to
  /// [0,1) within the chosen light's share, picks the point with u.y. Choice and point from one
  /// stratified 2D sample keep the point set on each light stratified (two separate samples
  /// would pick each triangle's points at random from a net), which matters for quads, two
  /// triangles of equal power; and a pixel's stratified u.x spread its samples over the lights
  /// in proportion to their probabilities.
  /// `normal` (unit, either side), where given, is the receiver's: the tree then bounds the
  /// receiver's cosine too.
  /// Without `withEnvironment` the environment is left out (the other lights chosen among
  /// themselves; no sample where it is the only light).
  /// With `cosineAbout` (a unit normal) a constant environment's direction is a one-sample
  /// mixture, three quarters cosine-weighted about the normal and a quarter uniform, the pdf
  /// the mixture's (a constant sky through a window then wastes few samples below the surface;
  /// a map keeps its own luminance sampler: mixing measured noisier under a bright patch).
  /// escapedPdf is the pdf without it.
  LightSample sampleLight(const Vec3& ref, const Vec2& u, bool withEnvironment = true,
                          const Vec3* cosineAbout = nullptr, const Vec3* normal = nullptr) const;
  /// Light samples towards `ref` with one 2D sample, as sampleLight takes them but with the light
  /// tree's adaptive splitting (LightTree::sampleSplit, render.lightSplitDeg > 0): where the
  /// bounded lights are chosen, up to LightTree::kMaxChoices of them, one from each group the
  /// tree splits into at ref, each sample's pdf that of its own group's choice (their
  /// estimates add up). Writes them to `out` (room for kMaxChoices); returns how many (one
  /// without splitting: sampleLight's). lightPdf and lightChoicePmf give these probabilities
  /// while splitting is on.
  int sampleLights(const Vec3& ref, const Vec2& u, bool withEnvironment, const Vec3* cosineAbout, const Vec3* normal,
                   LightSample* out) const;
  /// The environment's own sample, as sampleLight draws it once it has chosen the environment
  /// (`cosineAbout` likewise), its pdf the direction's alone (no choice among the lights); no
  /// sample without an environment.
  LightSample sampleEnvironment(const Vec3& ref, const Vec2& u, const Vec3* cosineAbout = nullptr) const;
  /// Solid-angle pdf of sampleLights (with the environment, and `normal` as given to it)
  /// choosing point `lightPos` on emissive `triangle` from ref: sampleLight's without splitting,
  /// else that of the choice in the light's own group.
  float lightPdf(const Vec3& ref, const Vec3* normal, uint32_t triangle, const Vec3& lightPos,
                 const Vec3& lightNormal) const;
  /// The probability that sampleLights (with the environment) chooses light `light` (the order
  /// of lightCount(): emissive triangles, point lights, directional lights, the environment),
  /// within its group where the tree splits.
  float lightChoicePmf(const Vec3& ref, const Vec3* normal, size_t light) const;
  /// Choose lights by the tree (true) or by power alone (false) from now on.
  void setLightTree(bool on) { render.lightTree = on; }
  /// The tree's split angle (degrees; 0: no splitting) from now on.
  void setLightSplit(float degrees) { render.lightSplitDeg = degrees; }
  /// Does sampleLights split (the tree chooses, with a split angle)?
  bool splitting() const { return render.lightTree && render.lightSplitDeg > 0.0f; }
  float splitAngle() const { return render.lightSplitDeg * (kPi / 180.0f); }  ///< radians
  /// Radiance arriving along a ray that leaves the scene in direction `dir` (unit): the
  /// environment's and that of every finite sun whose disc it meets; zero without them.
  Vec3 escaped(const Vec3& dir) const;
  /// The environment's alone (voxcone's cones gather the sky; the suns come by shadow rays).
  Vec3 escapedSky(const Vec3& dir) const { return environment ? environment->radiance(dir) : Vec3(0.0f); }
  /// escaped(), each light's share weighted by the power heuristic of `bsdfPdf` against
  /// sampleLight's solid-angle pdf of choosing that light in direction `dir` (path's MIS of
  /// rays that leave the scene after a non-specular bounce).
  Vec3 escapedMis(const Vec3& dir, float bsdfPdf) const;
  /// Solid-angle pdf of sampleLight choosing the environment in direction `dir`; zero without one.
  float escapedPdf(const Vec3& dir) const {
    return environment && !m_groupPmf.empty() ? m_groupPmf.back() * environment->pdf(dir) : 0.0f;
  }
  /// Total emitted power (W, luminance), for photon emission in part 2.
  float totalLightPower() const { return m_totalPower; }
  /// Triangle area in scene units squared.
  float triangleArea(uint32_t triangle) const;
  /// Number of emissive triangles.
  size_t emissiveTriangleCount() const { return m_emissiveTris.size(); }

  /// Summary statistics as JSON (counts, bounds).
  nlohmann::json statsJson() const;

private:
  Bounds3 m_bounds;
  std::vector<uint32_t> m_emissiveTris;    ///< light index i < size: triangle id
  std::vector<float> m_emissiveArea;       ///< per emissive triangle: its area
  std::vector<Vec3> m_emissiveNormal;      ///< per emissive triangle: its unit winding normal
  /// The choice among groups: [bounded lights (when any), directional lights..., environment],
  /// cumulative and per group, in proportion to power.
  std::vector<float> m_groupCdf;
  std::vector<float> m_groupPmf;
  bool m_hasBounded = false;
  size_t m_lightCount = 0;
  LightTree m_tree;                        ///< over the bounded lights
  /// Choose a light group (the bounded lights, each directional light, the environment) by
  /// power with u: the group, its probability and u rescaled within its share.
  bool chooseGroup(float u, bool withEnvironment, size_t& group, float& pmf, float& rescaled) const;
  /// The sample of light idx (lightCount()'s order), chosen with probability pmf, at point u.
  LightSample sampleChosen(const Vec3& ref, size_t idx, float pmf, const Vec2& u, const Vec3* cosineAbout) const;
  std::vector<float> m_boundedCdf;         ///< by power among the bounded lights (no tree)
  std::vector<float> m_boundedPmf;
  std::vector<int32_t> m_triLightIndex;    ///< per triangle: light index or -1
  float m_totalPower = 0.0f;
};

/// Load a scene: a Mitsuba 3 XML file when `path` ends in .xml (any case; scene/mitsuba.h),
/// else voxcone JSON (see docs/scenes.md). Relative mesh paths are resolved against the
/// scene file's folder. Throws SceneError naming the file and the JSON path or XML line.
Scene loadScene(const std::string& path);
/// loadScene with `-D name=value` parameters for a Mitsuba scene (they override its
/// `<default>` values); a JSON scene with any parameter is a SceneError.
Scene loadScene(const std::string& path, const std::map<std::string, std::string>& parameters);

/// Parse a scene from JSON text; `origin` names it in errors; `baseDir` resolves mesh paths.
Scene parseScene(const std::string& jsonText, const std::string& origin, const std::string& baseDir);

}  // namespace voxcone

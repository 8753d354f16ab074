#pragma once
/// \file cone_tracer.h
/// One cone marched through the voxel field's mips from a surface point, front to back, with an
/// exact HBVH segment along its axis first (voxel_cone.h describes the method: the lookup size
/// per step, the clearance of the own surface, linear occlusion, `exact_segment`, `gather`).

#include "voxcone/core/bounds.h"
#include "voxcone/core/math.h"
#include "voxcone/scene/scene.h"
#include "voxcone/voxel/voxel_field.h"

#include <optional>

namespace voxcone {

class Accel;
class Scene;
class PhotonRadiance;
class LightProximity;
class VoxelField;
struct VoxelConeSettings;

/// A surface fills voxels whose centres lie within half a voxel diagonal of it, sqrt(3)/2 v, and
/// a trilinear lookup at x takes the voxel centres inside the cube of half-side v around x,
/// which reaches |n|_1 v <= sqrt(3) v along a unit normal n: a lookup of voxel size v at
/// height h above a plane of any orientation does not see the plane when v <= h / kClearance.
/// (1 + sqrt(3)/2, right for axis-aligned planes only, let tilted and curved surfaces occlude
/// their own cones: cornell-box 38.73 dB at 16 spp, 40.06 dB with 4 gathers per 2x2 block;
/// 3 sqrt(3)/2: 38.97 and 40.70 dB. Gaussian mips reach further still and came out below box
/// mips at either value, docs/studies/mip-filter-*.)
constexpr float kClearance = 2.5980762f;
/// Where a cone's lookups are seen from (ConeSample::radiance shows each voxel's side facing
/// it): this many finest voxels above the shading point, clear of the centres of its own
/// surface's finest voxels (within sqrt(3)/2 v0 of it). (kClearance here cost the dragon 0.16 dB.)
constexpr float kApexLift = 1.0f + 0.8660254f;
/// Mirror and glass hits a cone continues through (reflected and refracted cones), and the
/// smallest lobe weight followed. Measured on the glass dragon at 4 spp: depth 2 / 3 / 4 gave
/// 31.71 / 31.84 / 31.92 dB (a cone entering glass needs the exit and an internal reflection
/// or two); a cut of 1e-3 (the delta chains', delta_chain.h) gave the same image to the bit.
constexpr int kMaxSpecularDepth = 4;
constexpr float kSpecularCut = 1e-2f;
/// A cone stops when 99% of it is covered: the rest can add at most 1% of its radiance.
constexpr float kOpaque = 0.99f;

/// Traces cones through one voxel field (immutable; trace() is called concurrently).
class ConeTracer {
public:
  /// Cones in `field` (levels built), exact segments against `accel` on `scene`'s triangles,
  /// with `settings`' step, maximum distance, exact segment and gather mode. Holds references.
  /// With settings.hitPhotons, the radiance at a cone's exact hit on a diffuse surface is the
  /// estimate of `photons` there (PhotonRadiance) instead of the field's finest level around
  /// it, plus, with settings.hitDirect, the hit's direct light by one shadow ray (the photons
  /// then hold only the light that bounced).
  /// With `proximity` (and photons), trace(nearSplit = true) takes at each diffuse hit y only the
  /// share LightProximity::coneShare(y) of its light, the caller the rest from the photons that
  /// left y (Photon::nearShare).
  ConeTracer(const Scene& scene, const Accel& accel, const VoxelField& field, const VoxelConeSettings& settings,
             const PhotonRadiance* photons = nullptr, const LightProximity* proximity = nullptr);
  /// The radiance one cone gathers from surface point p (rounding error pError, unit normal n
  /// on the side the cone leaves, unit direction d; dot(n, d) <= 0 gathers nothing), half-angle
  /// atan(tanHalf). Where the axis's exact ray meets a mirror or glass (delta materials), the
  /// cone's light there is what cones along its reflected and refracted directions gather
  /// from the hit, weighted by the lobes (`depth`: specular and glossy hits so far, up to
  /// kMaxSpecularDepth); at a glossy surface, continueGlossy's. `lightU`: the 2D sample of the light at the hit (hitDirect).
  /// With `sky`, a cone whose exact axis ray leaves the scene takes the environment's radiance
  /// along it (the caller leaves the environment out of its shadow rays); else nothing.
  /// With `axisHit` (gather = hit only), the surface the axis ray meets first, or nullopt where it
  /// leaves the scene (the caller's MIS of emission found by BSDF sampling). With `deltaLight`
  /// (gather = hit only), the emission (and sky) the axis finds through mirrors and glass is
  /// added there, weighted by their lobes: a glossy surface's view of a light in a mirror (L S G,
  /// which neither its light samples nor the caustic photons, stored at diffuse surfaces, carry).
  /// With `nearSplit` (and a proximity), the light of each diffuse hit beside a lamp counts only
  /// in its cone share (the constructor's), there and past mirrors, glass and glossy hits.
  Vec3 trace(const Vec3& p, const Vec3& pError, const Vec3& n, const Vec3& d, float tanHalf, const Vec2& lightU,
             int depth = 0, bool sky = false, std::optional<SurfaceHit>* axisHit = nullptr,
             Vec3* deltaLight = nullptr, bool nearSplit = false) const;
  float finestVoxel() const { return m_v0; }  ///< world units
  /// Per-axis variance of a cone's cross-section at unit distance along its axis, for
  /// directions uniform over its solid angle (half-angle atan(tanHalf)).
  static float crossSectionVariance(float tanHalf);
  int finestLevel() const { return m_finest; }

private:
  /// The exact hit of the ray from p (normal n) along d within tMax: distance, the surface,
  /// and its geometric normal turned towards the ray's side.
  struct AxisHit {
    float t = 0.0f;
    SurfaceHit surface;
    Vec3 side{0.0f};
  };
  /// The light a cone of direction d passes on at delta surface sh: its lobes' cones.
  Vec3 continueSpecular(const SurfaceHit& sh, const Vec3& d, float tanHalf, const Vec2& lightU, int depth,
                        Vec3* deltaLight, bool nearSplit) const;
  /// The light a cone of direction d passes on at glossy surface sh (neither delta nor diffuse:
  /// no photon estimate there): its direct light by one shadow ray and one cone along a
  /// direction its BSDF samples, as wide as its roughness (counted as a specular hit).
  Vec3 continueGlossy(const SurfaceHit& sh, const Vec3& d, const Vec2& lightU, int depth, bool nearSplit) const;
  /// The radiance a cone of direction d (apex `apex`) takes from the surface its exact ray hit
  /// (not a delta one), looked up in the field at voxel size v where there are no photons.
  Vec3 hitRadiance(const AxisHit& hit, const Vec3& d, const Vec3& apex, float v, const Vec2& lightU,
                   bool nearSplit) const;
  std::optional<AxisHit> hitAlongAxis(const Vec3& p, const Vec3& pError, const Vec3& n, const Vec3& d,
                                      float tMax) const;

  const Scene& m_scene;
  const Accel& m_accel;
  const VoxelField& m_field;
  const PhotonRadiance* m_photons = nullptr;
  const LightProximity* m_proximity = nullptr;
  float m_coneStep, m_maxDistance, m_exactSegment;  ///< exact segment in finest voxels
  bool m_hitGather;
  bool m_hitDirect;
  int m_hitLightSamples;  ///< shadow rays at a hit (VoxelConeSettings::hitLightSamples)
  bool m_hitEnvironment;  ///< m_hitDirect under a sky: its light at a hit where its photons are not kept
  float m_v0 = 0.0f;  ///< finest voxel size
  int m_finest = 0, m_coarsest = 0;
  Bounds3 m_fieldBounds;
  LookupFootprint m_footprint;
};

}  // namespace voxcone

#pragma once
/// \file photon_radiance.h
/// The diffuse radiance leaving one surface point, estimated from the photons that landed on
/// that surface, on that side, in sight of the point (Jensen 2001, eq. 7.6, with the photons
/// filtered as below): what a cone whose exact axis ray hit a surface takes from it.
///
/// Why not the voxel holding the hit: a voxel holds every surface that passes through it. The
/// two faces of a wall thinner than a voxel, a floor on both sides of that wall, a cup and the
/// table it stands on share voxels, and a lookup there (or a photon footprint spread over its
/// neighbours) hands one surface's light to the other: with the door closed, the unlit room
/// of data/scenes/failure/two-rooms-closed.json showed 13.6% of the lit room's light. Here a
/// photon counts for a point only if
///  - it arrived on the side the point is seen from (its normal within 60 degrees of the
///    point's side normal: a perpendicular wall's photons are another surface),
///  - it lies on the point's tangent plane (within a quarter of the search radius: the table's
///    photons are not the floor's beneath it), and
///  - the straight segment between the two, lifted off both surfaces, meets nothing (a wall
///    between them, however thin, stops it).
/// A closed room that no photon enters therefore estimates exactly zero.

#include "voxcone/core/math.h"
#include "voxcone/photon/photon_kdtree.h"
#include "voxcone/photon/photon_tracer.h"

#include <vector>

namespace voxcone {

class Accel;
class Scene;
struct SurfaceHit;

/// Settings of the estimate.
struct PhotonRadianceSettings {
  /// Photons per estimate: the k nearest (before filtering) set the disc's radius.
  int k = 64;
  /// Largest search radius, world units (> 0): where fewer than k photons lie inside it, the
  /// disc is this one.
  float maxRadius = 1.0f;
};

/// Photon density estimates at surface points with the filters above. Immutable after
/// construction; radiance() is thread-safe.
class PhotonRadiance {
public:
  PhotonRadiance() = default;
  /// Over `maps`' global and caustic photons (both: each pass carries the lights' whole flux for
  /// its own light paths, so their union estimates all diffuse radiance). Holds references to
  /// `scene` and `accel`.
  PhotonRadiance(const Scene& scene, const Accel& accel, const PhotonMaps& maps, const PhotonRadianceSettings& s);
  bool empty() const { return m_photons.empty(); }
  size_t size() const { return m_photons.size(); }
  /// Outgoing radiance (W / (sr m^2) per channel) on side `side` (unit: the geometric normal
  /// turned towards the viewer) of diffuse hit `hit`: albedo / pi times the irradiance estimate
  /// (Oren-Nayar surfaces taken as Lambertian); zero on surfaces that are not diffuse
  /// (Material::isDiffuse), as the field holds them.
  Vec3 radiance(const SurfaceHit& hit, const Vec3& side) const;
  /// Bytes held (photons and tree).
  size_t memoryBytes() const;

private:
  /// The fraction of the disc of radius r around `hit` (in its tangent plane, side `side`) that
  /// passes the photons' filters: the surface under it, in sight of `from` (the hit lifted by
  /// `lift`). At least 1 / kAreaProbes.
  float coveredFraction(const Vec3& x, const Vec3& side, const Vec3& from, float r, float lift) const;
  /// Incident irradiance (W / m^2 per channel) at surface point x (rounding error xError) on
  /// side `side`: the k nearest photons that pass the filters over the covered disc.
  Vec3 irradianceAt(const Vec3& x, const Vec3& xError, const Vec3& side) const;



  const Scene* m_scene = nullptr;
  const Accel* m_accel = nullptr;
  PhotonRadianceSettings m_settings;
  std::vector<Photon> m_photons;
  PhotonKdTree m_tree;
};

}  // namespace voxcone

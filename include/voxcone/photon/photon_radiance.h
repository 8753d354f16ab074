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
///
/// Precomputed irradiance (Christensen 1999, "Faster Photon Map Global Illumination"), an
/// option: the estimate above costs a k-nearest search, up to k visibility rays and the disc's
/// coverage probes, and every cone of a gather asks for one (70% of a render's time on the
/// failure suite). With `cacheStride` it is computed once at every cacheStride-th photon, on
/// that photon's side (when a lookup first needs it: small-objects estimates 37k of its 55k
/// entries), and a point takes the nearest such entry that passes the same filters
/// (its side, its tangent plane, in sight: one ray); where none does (a room no photon reached)
/// the full estimate runs: 4x faster gathers. An entry is estimated from the other photons only
/// (those whose index is not a multiple of the stride, carrying the left-out flux): estimated
/// from all of them, the entries' estimates were correlated with where they lie, and a point
/// takes an isolated entry (a large Voronoi cell, few photons around, a low estimate) more often
/// than a crowded one: -3.5% at k = 32 on a uniform floor, -12% at k = 8.

#include "voxcone/core/math.h"
#include "voxcone/photon/photon_kdtree.h"
#include "voxcone/photon/photon_tracer.h"

#include <atomic>
#include <memory>
#include <vector>

namespace voxcone {

class Accel;
class SeenRegion;
class Scene;
struct SurfaceHit;
struct Material;

/// Settings of the estimate.
struct PhotonRadianceSettings {
  /// Photons per estimate: the k nearest (before filtering) set the disc's radius.
  int k = 64;
  /// Largest search radius, world units (> 0): where fewer than k photons lie inside it, the
  /// disc is this one.
  float maxRadius = 1.0f;
  /// Irradiance precomputed at every cacheStride-th photon (0 or 1: none, every point estimates
  /// in full).
  int cacheStride = 0;
  /// Leave out the global photons straight from a light (bounces 0): the estimate is then the
  /// light that bounced at least once, for callers that take direct light by shadow rays.
  bool indirectOnly = false;
  /// With indirectOnly: keep the photons straight from the environment too, for callers that
  /// take the lamps' and suns' direct light by shadow rays and the sky's from the photons.
  bool skyDirect = false;
  /// Where given (the cells the gathers read, SeenRegion), the photons in its cells on sides
  /// it does not hold are left out, and the sky's straight photons outside it.
  std::shared_ptr<const SeenRegion> region = nullptr;
  /// Where only part of the disc is this surface in sight of the point (an edge, a corner), the
  /// light taken at the point by a linear fit over that part rather than as the part's mean.
  bool edgeFit = false;
  /// Whether the estimate uses photon p.
  bool keeps(const Photon& p) const;
  /// Whether the sky's straight photons at p (on the side facing n) are kept (skyDirect, in the
  /// region): where they are not, the sky's light there has to come another way.
  bool keepsSky(const Vec3& p, const Vec3& n) const;
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
  /// Over `photons` alone (PhotonMaps::glossyCaustic: for reflected()); no precomputed entries.
  PhotonRadiance(const Scene& scene, const Accel& accel, std::vector<Photon> photons, const PhotonRadianceSettings& s);
  bool empty() const { return m_photons.empty(); }
  size_t size() const { return m_photons.size(); }
  /// Outgoing radiance (W / (sr m^2) per channel) on side `side` (unit: the geometric normal
  /// turned towards the viewer) of diffuse hit `hit`: albedo / pi times the irradiance estimate
  /// (Oren-Nayar surfaces taken as Lambertian); zero on surfaces that are not diffuse
  /// (Material::isDiffuse), as the field holds them.
  Vec3 radiance(const SurfaceHit& hit, const Vec3& side) const;
  /// The irradiance estimate itself (W / m^2 per channel) on side `side` of `hit`, any surface.
  Vec3 irradiance(const SurfaceHit& hit, const Vec3& side) const;
  /// Outgoing radiance towards woWorld (unit, world space) on side
  /// `side` of any non-delta hit: the same filtered estimate, each photon weighted by the BSDF,
  /// sum f(wo, wi_p) Phi_p / (pi r^2 covered) (Jensen 2001, eq. 7.6: for photons that ended on
  /// glossy surfaces, whose reflection depends on where they came from).
  Vec3 reflected(const SurfaceHit& hit, const Vec3& side, const Vec3& woWorld) const;
  /// Bytes held (photons, the cache and their trees).
  size_t memoryBytes() const;
  /// Entries of the precomputed irradiance, and how many of them lookups have estimated so far.
  size_t cacheSize() const { return m_cache.size(); }
  size_t cacheEstimated() const;
  const PhotonRadianceSettings& settings() const { return m_settings; }

private:
  /// The part of the disc of radius r around x (in its tangent plane, side `side`, coordinates in
  /// Frame(side)'s s and t) that passes the photons' filters: the surface under it, in sight of
  /// `from` (x lifted by `lift`). Its share from kAreaProbes probes; with `shape`, where that is
  /// not the whole disc, its share and shape from kEdgeProbes.
  struct DiscCover {
    float fraction = 1.0f;   ///< its share of the disc, at least one probe's
    bool part = false;       ///< not the whole disc, and its shape below is known
    Vec2 centroid{0.0f};     ///< its centroid, relative to x
    float xx = 0.0f, xy = 0.0f, yy = 0.0f;  ///< its covariance
  };
  DiscCover cover(const Vec3& x, const Vec3& side, const Vec3& from, float r, float lift, bool shape) const;
  /// Surface point p (a photon's, a probe's) lifted along its unit normal n by `lift`, for a
  /// segment from `from` above x (side `side`). When p lies behind x's tangent plane, by half
  /// the way to the nearest surface along n instead, if that is nearer: a point on the inner
  /// face of a wall thinner than the lift stays inside the wall (lifted through it, a photon
  /// that slipped into a 1 cm roof slab through a seam lit the ceiling beneath it). Points on
  /// x's plane or before it take no ray: lifting them crosses no surface x lies on.
  Vec3 lifted(const Vec3& p, const Vec3& n, const Vec3& x, const Vec3& side, float lift) const;
  /// Incident irradiance (W / m^2 per channel) at surface point x (rounding error xError) on
  /// side `side`: the k nearest photons that pass the filters over the covered disc, whose
  /// radius goes to `radius`. With skipStride > 1 the photons whose index is a multiple of it
  /// (the cache's) are left out and the others carry their flux: an entry's estimate is then
  /// independent of where the entries lie.
  /// With `lobe`, each photon's power weighted by the BSDF towards the lobe's wo (reflected()).
  struct Lobe {
    const Material* material;
    Frame frame;  ///< the hit's shading frame
    Vec3 wo;      ///< in it
  };
  Vec3 irradianceAt(const Vec3& x, const Vec3& xError, const Vec3& side, float* radius = nullptr,
                    int skipStride = 0, const Lobe* lobe = nullptr) const;
  /// The tree over m_photons and, with cacheStride > 1, the precomputed entries.
  void build();
  /// The precomputed irradiance for x on side `side`: the nearest entry that passes the filters,
  /// or false.
  bool cachedIrradiance(const Vec3& x, const Vec3& xError, const Vec3& side, Vec3& out) const;

  /// One precomputed estimate: at a photon's position, on its side. Its estimate is made when a
  /// lookup first needs it (estimate()): a pure function of the photons, so the same whichever
  /// thread makes it first.
  struct CacheEntry {
    Vec3 position{0.0f}, normal{0.0f};
  };
  struct CacheEstimate {
    Vec3 irradiance{0.0f};
    float radius = 0.0f;  ///< the estimate's disc
  };
  /// Entry e's estimate, made now if no lookup made it before.
  CacheEstimate estimate(size_t e) const;

  const Scene* m_scene = nullptr;
  const Accel* m_accel = nullptr;
  PhotonRadianceSettings m_settings;
  std::vector<Photon> m_photons;
  PhotonKdTree m_tree;
  std::vector<CacheEntry> m_cache;
  /// Per entry: its estimate and its state (0 none, 1 being written, 2 written).
  mutable std::unique_ptr<CacheEstimate[]> m_estimates;
  mutable std::unique_ptr<std::atomic<uint8_t>[]> m_estimateState;
  PhotonKdTree m_cacheTree;
};

}  // namespace voxcone

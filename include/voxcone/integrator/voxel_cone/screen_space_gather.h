#pragma once
/// \file screen_space_gather.h
/// voxcone's screen-space gather protocol, which renderImage follows for an integrator that has
/// one (Integrator::screenSpaceGather): every pixel's samples are taken with the indirect light
/// of filterable first hits split off (liSplit), deferred gathers run at one pixel per
/// gatherSpacing block and wherever the filter cannot fill a pixel (gatherDeferred), the pixels
/// are linked where exact rays say their points see each other (linkIndirect, linkedPoints),
/// and a filter of indirectFilterRadius pixels carries the gathered light to the others
/// (integrator/indirect_filter.h). No other method gathers this way.

#include "voxcone/core/sampler.h"
#include "voxcone/scene/scene.h"

#include <cstdint>

namespace voxcone {

struct IndirectBuffer;

/// An indirect-light estimate at a sample's first hit that liSplit leaves for later
/// (ScreenSpaceGather::gatherDeferred): renderImage runs it only at the pixels that need it.
struct DeferredGather {
  SurfaceHit hit;        ///< the first hit
  Vec3 wo{0.0f};         ///< unit, towards the viewer, world space
  float u = 0.0f;        ///< the sample's random number for the estimate (voxcone: the cones' turn)
  float weight = 0.0f;   ///< the estimate's weight in the sample (voxcone: spp / gathers, or 1)
};

/// What one sample's first surface hands to the screen-space filter of indirect light
/// (ScreenSpaceGather::liSplit, renderImage).
struct IndirectSplit {
  Vec3 indirect{0.0f};   ///< the filterable part of the sample's radiance (not in liSplit's return)
  Vec3 position{0.0f};   ///< the first hit, world space
  Vec3 normal{0.0f};     ///< its unit geometric normal on the viewer's side
  uint32_t material = 0;
  /// What the filterable light is multiplied by after the filter: a textured albedo at the hit
  /// (the light is estimated without it, so that the filter does not blur the texture), else 1.
  Vec3 albedo{1.0f};
  bool valid = false;    ///< the first hit is a surface whose indirect light is filterable
  /// The sample's filterable indirect light is `gather`'s estimate (gatherDeferred) rather
  /// than `indirect`.
  bool deferred = false;
  DeferredGather gather;
};

/// What an integrator implements to render through the screen-space gather (see the file).
class ScreenSpaceGather {
public:
  virtual ~ScreenSpaceGather() = default;
  /// Radius in pixels of the screen-space filter renderImage applies to the indirect light
  /// liSplit separates (0: no filter, renderImage renders every sample whole).
  virtual int indirectFilterRadius() const = 0;
  /// Integrator::li, except that the indirect light of a filterable first hit goes into `split`
  /// (with the hit's position, normal and material) instead of the return value.
  virtual Vec3 liSplit(const Ray& ray, Sampler& sampler, IndirectSplit& split) const = 0;
  /// The weighted indirect-light estimate of a gather liSplit deferred (split.deferred).
  virtual Vec3 gatherDeferred(const DeferredGather& gather) const = 0;
  /// Spacing in pixels of the pixels whose deferred gathers renderImage runs: one pixel in each
  /// spacing x spacing block, plus every pixel the filter cannot fill from its neighbours
  /// (1: every pixel).
  virtual int gatherSpacing() const = 0;
  /// Fill buffer.link (indirect_filter.h) before the filter runs: which adjacent pixels' points
  /// see each other.
  virtual void linkIndirect(IndirectBuffer& buffer) const = 0;
  /// Whether nothing lies on the segment from `from` to `to` (two points just above one
  /// surface): the test behind linkIndirect's links, also used for the samples of pixels the
  /// filter does not take.
  virtual bool linkedPoints(const Vec3& from, const Vec3& to) const = 0;
};

}  // namespace voxcone

#pragma once
/// \file direct_light.h
/// Direct light at a surface by light sampling with shadow rays, shared by the integrators that
/// sample lights at their hits (whitted, pm, voxcone and its cones), and the power heuristic's
/// weight of the light a BSDF sample finds against those samples (Veach's multi-sample MIS).

#include "voxcone/core/math.h"
#include "voxcone/core/sampler.h"
#include "voxcone/scene/scene.h"

namespace voxcone {

class Accel;

/// Direct light at a non-delta surface by light sampling: one estimate with `samples` shadow
/// rays. wo is the unit direction towards the viewer (world space). Without `withEnvironment`
/// the environment is left out (Scene::sampleLights). With `bsdfSamples` > 0 each sample of an
/// area light or the environment is weighted by the power heuristic against that many BSDF
/// samples taken by the caller (Veach's multi-sample MIS: the caller weights the light its BSDF
/// samples find by the same heuristic, misWeightedEmission), and a constant environment is
/// sampled by its own sampler (the pdf escapedPdf gives); 0: light sampling alone.
Vec3 estimateDirectLight(const Scene& scene, const Accel& accel, const SurfaceHit& hit, const Vec3& wo, Sampler& sampler,
                         int samples, bool withEnvironment = true, int bsdfSamples = 0);
/// The emission a BSDF sample of direction wi (world, pdf bsdfPdf) finds at `light` (the first
/// surface along it) or, with `light` null, leaving the scene, weighted by the power heuristic
/// of `bsdfSamples` such samples against estimateDirectLight's `lightSamples` from `hit`.
Vec3 misWeightedEmission(const Scene& scene, const SurfaceHit& hit, const Vec3& wi, float bsdfPdf, int bsdfSamples,
                         int lightSamples, const SurfaceHit* light);
/// One sample of it: the light sampled at 2D point u, one shadow ray. With `minDistance` > 0 a
/// light point nearer than it counts as if it lay at that distance (its 1 / d^2 capped: the
/// clamp of instant radiosity), for callers whose point stands for an area of that radius.
Vec3 directLightSample(const Scene& scene, const Accel& accel, const SurfaceHit& hit, const Vec3& wo, const Vec2& u,
                       bool withEnvironment = true, float minDistance = 0.0f);
/// One sample of the environment's light alone (Scene::sampleEnvironment): with
/// directLightSample(..., false) an estimate of all direct light in which the sky's choice does
/// not starve the lamps (chosen by power, a sky seen through a window took most samples).
Vec3 environmentLightSample(const Scene& scene, const Accel& accel, const SurfaceHit& hit, const Vec3& wo, const Vec2& u);

}  // namespace voxcone

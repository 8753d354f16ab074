// Photon tracing (Jensen 2001, "Realistic Image Synthesis Using Photon Mapping", ch. 5; the
// flow of pbrt-v3's SPPM photon pass): emit from the lights by power, follow the HBVH, store
// at diffuse hits, continue by importance-sampling the BSDF with Russian roulette.

#include "voxcone/photon/photon_tracer.h"

#include "light_emission.h"
#include "voxcone/accel/accel.h"
#include "voxcone/core/error.h"
#include "voxcone/core/rng.h"
#include "voxcone/photon/emission_guide.h"
#include "voxcone/photon/light_proximity.h"
#include "voxcone/scene/bsdf.h"
#include "voxcone/scene/scene.h"

#include <nlohmann/json.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>

namespace voxcone {

nlohmann::json PhotonStats::toJson() const {
  const double emitted = double(emittedGlobal + emittedCaustic);
  return {{"emitted_global", emittedGlobal},
          {"emitted_caustic", emittedCaustic},
          {"stored_global", storedGlobal},
          {"stored_caustic", storedCaustic},
          {"stored_glossy_caustic", storedGlossyCaustic},
          {"emitted_power", {emittedPower.x, emittedPower.y, emittedPower.z}},
          {"seconds", seconds},
          {"photons_per_second", seconds > 0.0 ? emitted / seconds : 0.0}};
}

namespace {

/// Photons per work item: the unit of parallel work, of progress and of the cancel check.
/// The maps do not depend on it (every photon has its own random stream).
constexpr uint64_t kBlockSize = 4096;

enum class Pass : uint64_t { Global = 0, Caustic = 1 };

/// Trace photon `index` of the `count` of `pass` and append what it stores to `out` (and, with
/// `bins`, the emission guide's bin of each to `bins`; a caustic photon's glossy hit to
/// `glossyOut`). Each photon carries 1 / count of the
/// lights' flux, so that each pass carries it all.
void tracePhoton(const Scene& scene, const Accel& accel, const LightEmission& lights, const PhotonSettings& settings,
                 Pass pass, uint64_t index, uint64_t count, const Sphere& aim, std::vector<Photon>& out,
                 std::vector<EmissionSample>* samples, std::vector<Photon>& glossyOut) {
  // Stream (seed, p * 2^40 + i): 2^40 photons per pass before streams could overlap.
  Rng rng(settings.seed, (static_cast<uint64_t>(pass) << 40) + index);

  // Emission. The light choice is stratified over the pass, (index + u) / count: each light
  // (and, guided, each leaf of the guide) emits its share of the photons to within one, where
  // independent choices would leave a 16-light room's dimmest lights a few photons each, give
  // or take half. 32 random bits as a double (the CDF is double).
  EmittedPhoton e;
  EmissionSample u;
  u.uLight = std::min((double(index) + double(rng.nextU32()) * 0x1p-32) / double(count), std::nextafter(1.0, 0.0));
  u.uSide = rng.uniform();
  u.uPos = rng.uniform2();
  u.uDir = rng.uniform2();
  // The global pass through the emission guide: the same primary sample space, drawn by the
  // guide's density, each photon weighted by the uniform density over it.
  const EmissionGuide* guide = pass == Pass::Global ? settings.guide.get() : nullptr;
  const double guideWeight = guide ? guide->remap(u) : 1.0;
  const bool aimed = pass == Pass::Caustic && aim.radius >= 0.0f;
  if (!(aimed ? lights.sampleToward(u.uLight, u.uSide, u.uPos, u.uDir, aim, e)
              : lights.sample(u.uLight, u.uSide, u.uPos, u.uDir, e)))
    return;
  Vec3 power = Vec3(e.fluxWatts * (guideWeight / double(count)));
  if (!isFinite(power) || !(maxComponent(power) > 0.0f)) return;
  Ray ray = e.ray;

  // True while every bounce so far was a delta (specular) one; with at least one bounce, a
  // diffuse hit then ends a path L S+ D (a caustic).
  bool specularOnly = true;
  // The near share of the last diffuse surface the photon left (Photon::nearShare).
  float nearShare = 0.0f;
  const LightProximity* proximity = pass == Pass::Global ? settings.proximity.get() : nullptr;
  for (int segment = 1; segment <= settings.maxDepth; ++segment) {
    SurfaceHit sh;
    if (!intersectSurface(scene, accel, ray, sh)) return;  // escaped the scene
    const Vec3& pos = sh.position;
    const Vec3 woWorld = -glm::normalize(ray.dir);
    if (!isFinite(pos) || !isFinite(sh.shadingNormal) || !isFinite(woWorld)) return;
    Material textured;
    const Material& mat = scene.materialAt(sh, textured);

    // Store at diffuse hits only (Lambertian, Oren-Nayar, a coat's diffuse base): the voxel
    // field gathers diffuse radiance, and glossy lobes are not view-independent, so a glossy
    // hit stores nothing.
    if (mat.hasDiffuseBase()) {
      // A one-sided surface hit from behind reflects nothing: no photon, and the path ends
      // there (bsdfSample fails below), so its back never lights the field.
      if (mat.blackFrom(glm::dot(sh.shadingNormal, woWorld))) return;
      const bool caustic = specularOnly && segment > 1;
      if ((pass == Pass::Global ? !caustic : caustic)) {
        Photon ph;
        ph.position = pos;
        ph.power = power;
        ph.albedo = diffuseReflectance(mat);
        ph.incident = woWorld;
        ph.normal = glm::dot(sh.shadingNormal, woWorld) < 0.0f ? -sh.shadingNormal : sh.shadingNormal;
        ph.bounces = static_cast<uint8_t>(std::min(segment - 1, 255));
        ph.nearShare = nearShare;
        ph.fromEnvironment = e.environment ? 1 : 0;
        out.push_back(ph);
        if (samples) samples->push_back(u);
      }
      // A caustic path ends at its first diffuse hit: nothing after it is L S+ D.
      if (pass == Pass::Caustic) return;
      if (proximity) nearShare = 1.0f - proximity->coneShare(pos);
    } else if (pass == Pass::Caustic && !mat.isDelta()) {
      // A rough (glossy) bounce can never lead to L S+ D: the path ends here, kept where it
      // arrived after specular bounces only (L S+ G).
      if (specularOnly && segment > 1) {
        Photon ph;
        ph.position = pos;
        ph.power = power;
        ph.incident = woWorld;
        ph.normal = glm::dot(sh.shadingNormal, woWorld) < 0.0f ? -sh.shadingNormal : sh.shadingNormal;
        ph.bounces = static_cast<uint8_t>(std::min(segment - 1, 255));
        glossyOut.push_back(ph);
      }
      return;
    }
    if (segment == settings.maxDepth) return;

    // Continue by sampling the BSDF for importance (no 1/eta^2 on refraction: Veach 1997,
    // sec. 5.2). No adjoint shading-normal correction (Veach eq. 5.19): smooth normals only
    // tilt the cosine, as in pbrt-v3's SPPM.
    const Frame frame(sh.shadingNormal);
    const Vec3 wo = frame.toLocal(woWorld);
    BsdfSample bs;
    if (!bsdfSampleFrom(mat, wo, rng, bs, TransportMode::Importance)) return;
    Vec3 newPower = power * bs.weight;
    if (!bs.delta) {
      specularOnly = false;
      // Russian roulette at every non-delta bounce (Jensen 2001, sec. 5.3): survive with
      // q = min(1, max(new) / max(old)) and divide by q. For a Lambertian bounce of a grey
      // photon q is the albedo (Jensen's choice); in general the largest channel of a
      // surviving photon keeps its value, so photons keep comparable power, and a zero channel
      // never divides. Delta bounces skip roulette: their weight is at most one and maxDepth
      // bounds them.
      const float q = std::min(1.0f, maxComponent(newPower) / maxComponent(power));
      if (!(q > 0.0f)) return;
      if (q < 1.0f) {
        if (rng.uniform() >= q) return;
        newPower /= q;
      }
    }
    if (!isFinite(newPower) || !(maxComponent(newPower) > 0.0f)) return;
    power = newPower;
    ray = spawnRay(pos, sh.positionError, sh.geomNormal, glm::normalize(frame.toWorld(bs.wi)));
  }
}

}  // namespace

double lampPhotonShare(const Scene& scene) {
  const LightEmission lights(scene);
  double share = 0.0;
  for (size_t i = 0; i < lights.lightCount(); ++i) share += lights.local(i) ? lights.pmf(i) : 0.0;
  return share;
}

std::vector<double> lightChoiceEdges(const Scene& scene) {
  const LightEmission lights(scene);
  std::vector<double> edges;
  double c = 0.0;
  for (size_t i = 0; i + 1 < lights.lightCount(); ++i) {
    c += lights.pmf(i);
    if (c > 0.0 && c < 1.0 && (edges.empty() || c > edges.back())) edges.push_back(c);
  }
  return edges;
}

PhotonMaps tracePhotons(const Scene& scene, const Accel& accel, const PhotonSettings& settings, Progress* progress) {
  const auto t0 = std::chrono::steady_clock::now();
  Progress nullProgress;
  Progress& prog = progress ? *progress : nullProgress;
  PhotonMaps maps;
  LightEmission lights(scene, settings.localOnly);
  lights.setDistantTarget(settings.distantTarget, settings.distantShare);
  // Where caustic photons are aimed: the bounding sphere of the delta triangles (none: not aimed).
  Sphere aim;
  if (settings.aimCaustics) {
    Bounds3 specular;
    for (size_t t = 0; t < scene.triangles.size(); ++t)
      if (scene.materials[scene.triMaterial[t]].hasDeltaLobe())
        for (uint32_t v : {scene.triangles[t].x, scene.triangles[t].y, scene.triangles[t].z}) specular.extend(scene.positions[v]);
    if (!specular.empty()) {
      aim.center = 0.5f * (specular.lo + specular.hi);
      // Half the diagonal, a little more so that rounding never cuts off a corner.
      aim.radius = 0.5f * glm::length(specular.hi - specular.lo) * (1.0f + 1e-4f) + 1e-30f;
    }
  }

  // Nothing is emitted without a light: both maps stay empty.
  const uint64_t counts[2] = {lights.empty() ? 0 : settings.photons, lights.empty() ? 0 : settings.causticPhotons};
  const uint64_t blocks[2] = {(counts[0] + kBlockSize - 1) / kBlockSize, (counts[1] + kBlockSize - 1) / kBlockSize};
  prog.start("photons", counts[0] + counts[1]);

  // One parallel loop over the blocks of both passes; block b collects into perBlock[b], and
  // the blocks are concatenated in order, so the maps do not depend on the thread count.
  std::vector<std::vector<Photon>> perBlock(blocks[0] + blocks[1]), perBlockGlossy(blocks[0] + blocks[1]);
  const bool record = settings.recordSamples;
  std::vector<std::vector<EmissionSample>> perBlockSamples(record ? blocks[0] : 0);
  std::atomic<bool> cancelled{false};
  tbb::parallel_for(tbb::blocked_range<uint64_t>(0, perBlock.size(), 1), [&](const tbb::blocked_range<uint64_t>& r) {
    for (uint64_t b = r.begin(); b != r.end(); ++b) {
      if (cancelled.load(std::memory_order_relaxed) || prog.cancelled()) {
        cancelled = true;
        return;
      }
      const Pass pass = b < blocks[0] ? Pass::Global : Pass::Caustic;
      const uint64_t p = static_cast<uint64_t>(pass);
      const uint64_t first = (b - (pass == Pass::Global ? 0 : blocks[0])) * kBlockSize;
      const uint64_t last = std::min(counts[p], first + kBlockSize);
      std::vector<Photon>& out = perBlock[b];
      std::vector<EmissionSample>* samples = record && pass == Pass::Global ? &perBlockSamples[b] : nullptr;
      for (uint64_t i = first; i < last; ++i)
        tracePhoton(scene, accel, lights, settings, pass, i, counts[p], aim, out, samples, perBlockGlossy[b]);
      prog.advance(last - first);
    }
  });
  if (cancelled) throw CancelledError();

  // Concatenate in block order.
  size_t sizes[2] = {0, 0};
  for (uint64_t b = 0; b < perBlock.size(); ++b) sizes[b < blocks[0] ? 0 : 1] += perBlock[b].size();
  maps.global.reserve(sizes[0]);
  maps.caustic.reserve(sizes[1]);
  for (uint64_t b = 0; b < perBlock.size(); ++b) {
    std::vector<Photon>& dst = b < blocks[0] ? maps.global : maps.caustic;
    dst.insert(dst.end(), perBlock[b].begin(), perBlock[b].end());
    std::vector<Photon>().swap(perBlock[b]);
    maps.glossyCaustic.insert(maps.glossyCaustic.end(), perBlockGlossy[b].begin(), perBlockGlossy[b].end());
  }
  if (record) {
    maps.globalSamples.reserve(sizes[0]);
    for (const std::vector<EmissionSample>& samples : perBlockSamples)
      maps.globalSamples.insert(maps.globalSamples.end(), samples.begin(), samples.end());
  }
  prog.finish();

  maps.stats.emittedGlobal = counts[0];
  maps.stats.emittedCaustic = counts[1];
  maps.stats.storedGlobal = maps.global.size();
  maps.stats.storedCaustic = maps.caustic.size();
  maps.stats.storedGlossyCaustic = maps.glossyCaustic.size();
  maps.stats.emittedPower = Vec3(lights.totalFlux());
  maps.stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return maps;
}

}  // namespace voxcone

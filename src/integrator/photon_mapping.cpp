// Photon mapping (Jensen 2001, "Realistic Image Synthesis Using Photon Mapping", ch. 7-9).

#include "voxcone/integrator/photon_mapping.h"

#include "options.h"
#include "voxcone/accel/accel.h"
#include "voxcone/core/error.h"
#include "voxcone/core/sampling.h"
#include "voxcone/integrator/direct_light.h"
#include "voxcone/scene/bsdf.h"

#include <chrono>
#include <cmath>
#include <limits>

namespace voxcone {

namespace {
/// Positions of a photon list, for the kd-tree.
std::vector<Vec3> positionsOf(const std::vector<Photon>& photons) {
  std::vector<Vec3> out(photons.size());
  for (size_t i = 0; i < photons.size(); ++i) out[i] = photons[i].position;
  return out;
}
}  // namespace

PhotonMappingIntegrator::PhotonMappingIntegrator(const IntegratorContext& c)
    : m_scene(c.scene), m_accel(c.accel), m_maxDepth(c.settings.maxDepth) {
  OptionReader r(c.options, "pm");
  const float sceneRadius = std::max(0.0f, m_scene.boundingSphere().radius);
  const double defaultRadius = sceneRadius > 0.0f ? 0.05 * sceneRadius : 1.0;  // empty scene: any radius finds nothing
  m_maxRadius = static_cast<float>(r.number("max_radius", defaultRadius, 1e-30, 1e30));
  constexpr int kMaxInt = std::numeric_limits<int>::max();
  uint64_t photons, causticPhotons;
  defaultPhotonCounts(c.settings.photons, c.settings.causticPhotons, kPhotonMappingDefaultPhotons, 0, photons,
                      causticPhotons);
  m_photonSettings.photons =
      static_cast<uint64_t>(r.integer("photons", static_cast<int>(std::min<uint64_t>(photons, kMaxInt)), 0, kMaxInt));
  m_photonSettings.causticPhotons = static_cast<uint64_t>(
      r.integer("caustic_photons", static_cast<int>(std::min<uint64_t>(causticPhotons, kMaxInt)), 0, kMaxInt));
  m_k = r.integer("k", 100, 1, 10000);
  m_finalGather = r.integer("final_gather", 0, 0, 65536);
  m_photonSettings.seed = c.settings.seed + static_cast<uint64_t>(r.integer("seed", 0, 0, kMaxInt));
  r.finish();
  m_photonSettings.maxDepth = std::max(1, m_maxDepth);

  // No delta material: no light path L S+ D exists, so the caustic pass would store nothing.
  bool anyDelta = false;
  for (const Material& m : m_scene.materials) anyDelta = anyDelta || m.hasDeltaLobe();
  if (!anyDelta) m_photonSettings.causticPhotons = 0;
}

nlohmann::json PhotonMappingIntegrator::settingsJson() const {
  return {{"max_depth", m_maxDepth},
          {"photons", m_photonSettings.photons},
          {"caustic_photons", m_photonSettings.causticPhotons},
          {"k", m_k},
          {"max_radius", m_maxRadius},
          {"final_gather", m_finalGather},
          {"photon_seed", m_photonSettings.seed}};
}

nlohmann::json PhotonMappingIntegrator::statsJson() const {
  nlohmann::json j = m_maps.stats.toJson();
  j["photon_trace_seconds"] = m_maps.stats.seconds;
  j["kdtree_build_seconds"] = m_buildSeconds;
  j["photon_bytes"] = (m_maps.global.size() + m_maps.caustic.size()) * sizeof(Photon);
  return j;
}

void PhotonMappingIntegrator::prepare(Progress* progress) {
  m_maps = tracePhotons(m_scene, m_accel, m_photonSettings, progress);
  const auto t0 = std::chrono::steady_clock::now();
  Progress nullProgress;
  Progress& prog = progress ? *progress : nullProgress;
  prog.start("kd-trees", 2);
  m_globalTree = PhotonKdTree(positionsOf(m_maps.global));
  prog.advance(1);
  m_causticTree = PhotonKdTree(positionsOf(m_maps.caustic));
  prog.advance(1);
  prog.finish();
  m_buildSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

Vec3 PhotonMappingIntegrator::estimate(const PhotonKdTree& tree, const std::vector<Photon>& photons,
                                       bool indirectOnly, const SurfaceHit& hit, const Vec3& woWorld) const {
  if (tree.empty()) return Vec3(0.0f);
  thread_local std::vector<KdNeighbor> neighbors;
  const float maxDist2 = m_maxRadius * m_maxRadius;
  const size_t found = tree.knn(hit.position, m_k, maxDist2, neighbors);
  if (found == 0) return Vec3(0.0f);
  // r is the distance to the k-th photon; with fewer than k inside max_radius the searched
  // disc is the max_radius one (Jensen's locate_photons keeps dist2 = max^2 until the heap
  // is full).
  const float r2 = found == static_cast<size_t>(m_k) ? neighbors.back().dist2 : maxDist2;
  if (!(r2 > 0.0f)) return Vec3(0.0f);

  Material textured;
  const Material& mat = m_scene.materialAt(hit, textured);
  const Frame frame(hit.shadingNormal);
  const Vec3 wo = frame.toLocal(woWorld);
  // The viewer's side of the surface: photons that arrived on the other side of a thin wall
  // do not light this side.
  const Vec3 side = glm::dot(hit.shadingNormal, woWorld) < 0.0f ? -hit.shadingNormal : hit.shadingNormal;
  Vec3 sum(0.0f);
  for (size_t i = 0; i < found; ++i) {
    const Photon& ph = photons[neighbors[i].index];
    if (indirectOnly && ph.bounces == 0) continue;
    if (glm::dot(ph.normal, side) <= 0.0f) continue;
    sum += bsdfEval(mat, wo, frame.toLocal(ph.incident)) * ph.power;
  }
  // Jensen eq. 7.6: L = sum f * Phi / (pi r^2).
  return sum / (kPi * r2);
}

Vec3 PhotonMappingIntegrator::gather(Ray ray, Sampler& sampler, int depth) const {
  Vec3 beta(1.0f), L(0.0f);
  // Emission found right from the gather origin or through delta bounces from it is direct
  // light or a caustic there (both estimated otherwise); it counts only when reached by delta
  // bounces from a glossy vertex of this gather path (no shadow ray samples that).
  bool seenGlossy = false, countEmission = false;
  for (; depth < m_maxDepth; ++depth) {
    SurfaceHit sh;
    if (!intersectSurface(m_scene, m_accel, ray, sh)) {
      if (countEmission) L += beta * m_scene.escaped(glm::normalize(ray.dir));
      break;
    }
    const Vec3& pos = sh.position;
    const Vec3 woWorld = -glm::normalize(ray.dir);
    Material textured;
    const Material& mat = m_scene.materialAt(sh, textured);
    if (countEmission) L += beta * m_scene.emitted(sh, woWorld);
    // Diffuse: the full radiance estimate (direct photons included) plus caustics here.
    if (mat.isDiffuse())
      return L + beta * (estimate(m_globalTree, m_maps.global, false, sh, woWorld) +
                         estimate(m_causticTree, m_maps.caustic, false, sh, woWorld));
    // Glossy: no photons are stored here; direct light by a shadow ray, then continue.
    if (!mat.isDelta()) {
      L += beta * estimateDirectLight(m_scene, m_accel, sh, woWorld, sampler, 1);
      seenGlossy = true;
    }
    if (depth + 1 >= m_maxDepth) break;
    const Frame frame(sh.shadingNormal);
    BsdfSample bs;
    if (!bsdfSampleFrom(mat, frame.toLocal(woWorld), sampler, bs)) break;
    beta *= bs.weight;
    countEmission = seenGlossy && bs.delta;
    ray = spawnRay(pos, sh.positionError, sh.geomNormal, frame.toWorld(bs.wi));
  }
  return L;
}

Vec3 PhotonMappingIntegrator::li(const Ray& cameraRay, Sampler& sampler) const {
  Vec3 L(0.0f), beta(1.0f);
  Ray ray = cameraRay;
  // Emission counts when seen from the camera or through a delta bounce: right after a glossy
  // bounce it is direct light at the glossy vertex, sampled there by shadow rays.
  bool countEmission = true;
  for (int depth = 0;; ++depth) {
    SurfaceHit sh;
    if (!intersectSurface(m_scene, m_accel, ray, sh)) {
      if (countEmission) L += beta * m_scene.escaped(glm::normalize(ray.dir));
      break;
    }
    const Vec3& pos = sh.position;
    const Vec3 woWorld = -glm::normalize(ray.dir);
    Material textured;
    const Material& mat = m_scene.materialAt(sh, textured);
    if (countEmission) L += beta * m_scene.emitted(sh, woWorld);

    if (!mat.isDelta()) {
      // Direct light by shadow rays (Jensen eq. 9.8, L_l).
      L += beta * estimateDirectLight(m_scene, m_accel, sh, woWorld, sampler, 1);
      if (mat.isDiffuse()) {
        // Caustics from the caustic map (L_c), then indirect diffuse light (L_d).
        Vec3 Lr = estimate(m_causticTree, m_maps.caustic, false, sh, woWorld);
        if (m_finalGather == 0) {
          Lr += estimate(m_globalTree, m_maps.global, true, sh, woWorld);
        } else if (depth + 1 < m_maxDepth) {
          // Final gathering: cosine-distributed rays, weight f * cos / pdf = f * pi.
          const Frame frame(sh.shadingNormal);
          const Vec3 wo = frame.toLocal(woWorld);
          const float flip = wo.z < 0.0f ? -1.0f : 1.0f;  // gather on the viewer's side
          Vec3 sum(0.0f);
          for (int i = 0; i < m_finalGather; ++i) {
            Vec3 wi = sampleCosineHemisphere(sampler.uniform2());
            wi.z *= flip;
            const Vec3 f = bsdfEval(mat, wo, wi);
            if (isBlack(f)) continue;
            sum += f * kPi * gather(spawnRay(pos, sh.positionError, sh.geomNormal, frame.toWorld(wi)), sampler, depth + 1);
          }
          Lr += sum / static_cast<float>(m_finalGather);
        }
        L += beta * Lr;
        break;
      }
      // Glossy: continue by BSDF sampling (Jensen's L_s term by Monte Carlo ray tracing).
    }
    if (depth + 1 >= m_maxDepth) break;

    // Delta or glossy bounce: sample the BSDF with the pixel's stream.
    const Frame frame(sh.shadingNormal);
    BsdfSample bs;
    if (!bsdfSampleFrom(mat, frame.toLocal(woWorld), sampler, bs)) break;
    beta *= bs.weight;
    countEmission = bs.delta;
    ray = spawnRay(pos, sh.positionError, sh.geomNormal, frame.toWorld(bs.wi));
  }
  return L;
}

}  // namespace voxcone

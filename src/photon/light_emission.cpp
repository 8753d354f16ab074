#include "light_emission.h"

#include "voxcone/core/sampling.h"
#include "voxcone/scene/scene.h"

namespace voxcone {

namespace {
/// Rec. 709 luminance in double precision (the weights of voxcone::luminance).
double luminanceD(const DVec3& rgb) { return 0.2126 * rgb.x + 0.7152 * rgb.y + 0.0722 * rgb.z; }
}  // namespace

LightEmission::LightEmission(const Scene& scene) : m_scene(scene) {
  // Emissive triangles: flux of a Lambertian emitter, pi * Le * A per emitting side.
  std::vector<double> power;
  for (uint32_t t = 0; t < scene.triangles.size(); ++t) {
    const Material& m = scene.materials[scene.triMaterial[t]];
    if (!m.isEmissive()) continue;
    const double area = scene.triangleArea(t);
    if (!(area > 0.0) || !std::isfinite(area)) continue;
    Light l;
    l.triangle = t;
    l.twoSided = m.twoSidedEmission;
    l.fluxWatts = double(kPi) * glm::max(DVec3(m.emission), DVec3(0.0)) * area * (l.twoSided ? 2.0 : 1.0);
    const double lum = luminanceD(l.fluxWatts);
    if (!(lum > 0.0) || !std::isfinite(lum)) continue;
    m_lights.push_back(l);
    power.push_back(lum);
  }
  // Point lights: an isotropic source of intensity I emits 4 pi I.
  for (size_t i = 0; i < scene.pointLights.size(); ++i) {
    Light l;
    l.pointLight = static_cast<int32_t>(i);
    l.fluxWatts = 4.0 * double(kPi) * glm::max(DVec3(scene.pointLights[i].intensity), DVec3(0.0));
    const double lum = luminanceD(l.fluxWatts);
    if (!(lum > 0.0) || !std::isfinite(lum)) continue;
    m_lights.push_back(l);
    power.push_back(lum);
  }

  // Choice in proportion to luminance; the RGB flux rides along (divided by the pmf on emission).
  double total = 0.0;
  for (double p : power) total += p;
  if (!(total > 0.0) || !std::isfinite(total)) {
    m_lights.clear();
    return;
  }
  m_cdf.resize(power.size());
  m_pmf.resize(power.size());
  double acc = 0.0;
  for (size_t i = 0; i < power.size(); ++i) {
    acc += power[i];
    m_pmf[i] = power[i] / total;
    m_cdf[i] = acc / total;
    m_totalFlux += m_lights[i].fluxWatts;
  }
  m_cdf.back() = 1.0;
}

bool LightEmission::sample(double uLight, float uSide, const Vec2& uPos, const Vec2& uDir, EmittedPhoton& out) const {
  if (m_cdf.empty()) return false;
  // Choose a light by power (binary search in the CDF).
  const size_t idx = std::min(static_cast<size_t>(std::upper_bound(m_cdf.begin(), m_cdf.end(), uLight) - m_cdf.begin()),
                              m_cdf.size() - 1);
  const Light& light = m_lights[idx];
  // Flux / pmf: the one-sample estimate of the total flux (its mean over the choice is exact
  // per channel even when the lights differ in colour).
  out.fluxWatts = light.fluxWatts / m_pmf[idx];

  if (light.pointLight >= 0) {
    // Point light: uniform direction on the sphere; no surface, so no offset.
    out.ray = Ray();
    out.ray.origin = m_scene.pointLights[static_cast<size_t>(light.pointLight)].position;
    out.ray.dir = sampleUniformSphere(uDir);
    return true;
  }

  // Emissive triangle: uniform point, cosine-weighted direction on the emitting side. The
  // density (1/A) (cos/pi) (1/sides) against Le cos makes the weight exactly the flux
  // pi Le A sides, already in fluxWatts.
  const UVec3& tri = m_scene.triangles[light.triangle];
  const Vec3& p0 = m_scene.positions[tri.x];
  const Vec3& p1 = m_scene.positions[tri.y];
  const Vec3& p2 = m_scene.positions[tri.z];
  const Vec2 b = sampleUniformTriangle(uPos);
  Vec3 pError;
  const Vec3 p = barycentricPoint(p0, p1, p2, 1.0f - b.x - b.y, b.x, b.y, pError);
  // The geometric normal from the winding is the front side (Scene::emitted).
  Vec3 n = glm::normalize(glm::cross(p1 - p0, p2 - p0));
  if (light.twoSided && uSide < 0.5f) n = -n;
  const Vec3 dir = glm::normalize(Frame(n).toWorld(sampleCosineHemisphere(uDir)));
  if (!isFinite(dir) || !isFinite(p)) return false;
  out.ray = spawnRay(p, pError, n, dir);
  return true;
}

}  // namespace voxcone

#include "light_emission.h"

#include "voxcone/core/sampling.h"
#include "voxcone/scene/scene.h"

namespace voxcone {

namespace {
/// Rec. 709 luminance in double precision (the weights of voxcone::luminance).
double luminanceD(const DVec3& rgb) { return 0.2126 * rgb.x + 0.7152 * rgb.y + 0.0722 * rgb.z; }
}  // namespace

LightEmission::LightEmission(const Scene& scene, bool localOnly) : m_scene(scene), m_sphere(scene.boundingSphere()) {
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

  // Directional lights: the flux through the bounding sphere's cross-section, E pi R^2.
  for (size_t i = 0; i < (localOnly ? 0 : scene.directionalLights.size()); ++i) {
    Light l;
    l.directional = static_cast<int32_t>(i);
    const double r = double(m_sphere.radius);
    l.fluxWatts = double(kPi) * r * r * glm::max(DVec3(scene.directionalLights[i].irradiance), DVec3(0.0));
    const double lum = luminanceD(l.fluxWatts);
    if (!(lum > 0.0) || !std::isfinite(lum)) continue;
    m_lights.push_back(l);
    power.push_back(lum);
  }

  // The environment: pi R^2 times its radiance's integral over the sphere (the flux through a
  // disc of radius R facing each direction).
  if (scene.environment && !localOnly) {
    Light l;
    l.environment = true;
    const double r = double(m_sphere.radius);
    l.fluxWatts = double(kPi) * r * r * glm::max(DVec3(scene.environment->integral()), DVec3(0.0));
    const double lum = luminanceD(l.fluxWatts);
    if (lum > 0.0 && std::isfinite(lum)) {
      m_lights.push_back(l);
      power.push_back(lum);
    }
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

void LightEmission::setDistantTarget(const Sphere& target, double share) {
  m_distantTarget = Sphere();
  m_distantShare = 0.0;
  if (!(target.radius > 0.0f) || !(share > 0.0 && share < 1.0) || !isFinite(target.center)) return;
  // A target as large as the scene gains nothing.
  if (!(target.radius < m_sphere.radius)) return;
  m_distantTarget = target;
  m_distantShare = share;
}

Vec3 LightEmission::discPoint(const Vec3& d, const Vec3& centre, float radius, bool targeted, float uChoice,
                              const Vec2& u, double& areaPdf) const {
  const Vec3 discC = discCentre(d);
  const Frame frame(d);
  // The projection of a point onto the disc's plane (through discC, across d).
  const auto onPlane = [&](const Vec3& p) { return p - d * glm::dot(p - discC, d); };
  const Vec3 whole = onPlane(centre);
  const double wholeArea = double(kPi) * double(radius) * double(radius);
  if (!targeted || !(m_distantTarget.radius > 0.0f)) {
    areaPdf = 1.0 / wholeArea;
    return whole + frame.toWorld(Vec3(sampleConcentricDisk(u) * radius, 0.0f));
  }
  const Vec3 target = onPlane(m_distantTarget.center);
  const float r = m_distantTarget.radius;
  const double targetArea = double(kPi) * double(r) * double(r);
  const bool toTarget = double(uChoice) < m_distantShare;
  const Vec3 p = toTarget ? target + frame.toWorld(Vec3(sampleConcentricDisk(u) * r, 0.0f))
                          : whole + frame.toWorld(Vec3(sampleConcentricDisk(u) * radius, 0.0f));
  // The mixture's density at p: each part's where p lies in it (the target part may reach past
  // the whole disc; its rays there miss the scene).
  const auto inside = [](const Vec3& q, const Vec3& c, float rad) {
    return glm::dot(q - c, q - c) <= rad * rad * 1.0001f;
  };
  areaPdf = (inside(p, whole, radius) ? (1.0 - m_distantShare) / wholeArea : 0.0) +
            (inside(p, target, r) ? m_distantShare / targetArea : 0.0);
  if (!(areaPdf > 0.0)) areaPdf = (toTarget ? m_distantShare / targetArea : (1.0 - m_distantShare) / wholeArea);
  return p;
}

Vec3 LightEmission::discCentre(const Vec3& direction) const {
  // 1% outside the sphere: a point of the disc lies at least that far from the scene.
  return m_sphere.center - direction * (1.01f * m_sphere.radius + 1e-6f);
}

size_t LightEmission::choose(double uLight) const {
  // By power: binary search in the CDF.
  return std::min(static_cast<size_t>(std::upper_bound(m_cdf.begin(), m_cdf.end(), uLight) - m_cdf.begin()),
                  m_cdf.size() - 1);
}

Vec3 LightEmission::pointOn(const Light& light, const Vec2& uPos, Vec3& pError, Vec3& frontNormal) const {
  const UVec3& tri = m_scene.triangles[light.triangle];
  const Vec3& p0 = m_scene.positions[tri.x];
  const Vec3& p1 = m_scene.positions[tri.y];
  const Vec3& p2 = m_scene.positions[tri.z];
  const Vec2 b = sampleUniformTriangle(uPos);
  // The geometric normal from the winding is the front side (Scene::emitted).
  frontNormal = glm::normalize(glm::cross(p1 - p0, p2 - p0));
  return barycentricPoint(p0, p1, p2, 1.0f - b.x - b.y, b.x, b.y, pError);
}

namespace {
/// A photon's direction from sun `dl`: its own, or uniform in a finite sun's cone (uPos: the
/// emitting disc's point takes uDir). Each photon keeps E pi R^2: the flux through a disc
/// facing a direction of the cone differs from it by a factor cos, 1 - 2e-6 for the real sun.
Vec3 sunDirection(const DirectionalLight& dl, const Vec2& u) {
  if (dl.isDelta()) return dl.direction;
  return glm::normalize(Frame(dl.direction).toWorld(sampleUniformCone(u, dl.oneMinusCos())));
}
}  // namespace

bool LightEmission::sample(double uLight, float uSide, const Vec2& uPos, const Vec2& uDir, EmittedPhoton& out) const {
  if (m_cdf.empty()) return false;
  const size_t idx = choose(uLight);
  const Light& light = m_lights[idx];
  // Flux / pmf: the one-sample estimate of the total flux (its mean over the choice is exact
  // per channel even when the lights differ in colour).
  out.fluxWatts = light.fluxWatts / m_pmf[idx];

  if (light.environment) return sampleEnvironment(idx, true, uSide, uPos, uDir, m_sphere.center, m_sphere.radius, out);

  if (light.directional >= 0) {
    // A uniform point on the disc of radius R across the light, outside the scene: every ray
    // of the light that meets the scene starts on it, each carrying E pi R^2 / photons.
    const DirectionalLight& dl = m_scene.directionalLights[static_cast<size_t>(light.directional)];
    const Vec3 d = sunDirection(dl, uPos);
    double areaPdf = 0.0;
    out.ray = Ray();
    out.ray.origin = discPoint(d, m_sphere.center, m_sphere.radius, true, uSide, uDir, areaPdf);
    out.ray.dir = d;
    // The light's flux E pi R^2 is the whole disc's; a point drawn at another density carries it
    // times the whole disc's density over the point's.
    out.fluxWatts /= areaPdf * double(kPi) * double(m_sphere.radius) * double(m_sphere.radius);
    return isFinite(out.ray.origin);
  }

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
  Vec3 pError, n;
  const Vec3 p = pointOn(light, uPos, pError, n);
  if (light.twoSided && uSide < 0.5f) n = -n;
  const Vec3 dir = glm::normalize(Frame(n).toWorld(sampleCosineHemisphere(uDir)));
  if (!isFinite(dir) || !isFinite(p)) return false;
  out.ray = spawnRay(p, pError, n, dir);
  return true;
}

bool LightEmission::sampleEnvironment(size_t idx, bool targeted, float uChoice, const Vec2& uPos, const Vec2& uDir,
                                      const Vec3& centre, float radius, EmittedPhoton& out) const {
  // A direction w from the environment's sampler (uDir: the emission guide's cell), then a
  // uniform point on the disc of radius r facing w, outside the scene's bounding sphere,
  // centred on the line through `centre` along w: every ray from that direction whose first
  // hit lies in the sphere of radius r around `centre` starts on it. Weight L(w) pi r^2 /
  // pdf(w) / pmf (pbrt-v4's ImageInfiniteLight::SampleLe).
  float pdfDir = 0.0f;
  const Vec3 w = m_scene.environment->sample(uDir, pdfDir);
  if (!(pdfDir > 0.0f)) return false;
  const Vec3 d = -w;  // the photon travels from the sky into the scene
  double areaPdf = 0.0;
  out.ray = Ray();
  out.ray.origin = discPoint(d, centre, radius, targeted, uChoice, uPos, areaPdf);
  out.ray.dir = d;
  out.fluxWatts = DVec3(m_scene.environment->radiance(w)) / areaPdf / double(pdfDir) / m_pmf[idx];
  out.environment = true;
  return isFinite(out.ray.origin) && isFinite(out.ray.dir);
}

bool LightEmission::sampleToward(double uLight, float uSide, const Vec2& uPos, const Vec2& uDir, const Sphere& target,
                                 EmittedPhoton& out) const {
  if (m_cdf.empty()) return false;
  const size_t idx = choose(uLight);
  const Light& light = m_lights[idx];
  if (light.environment) {
    if (!(target.radius >= 0.0f)) return sample(uLight, uSide, uPos, uDir, out);
    return sampleEnvironment(idx, false, 0.0f, uPos, uDir, target.center, std::min(target.radius, m_sphere.radius), out);
  }
  if (light.directional >= 0) {
    // The paths whose first hit lies in the target start in the disc of its radius around the
    // target's centre projected onto the emitting disc: uniform there, E pi r^2 each.
    const Vec3 d = sunDirection(m_scene.directionalLights[static_cast<size_t>(light.directional)], uPos);
    if (!(target.radius >= 0.0f)) return sample(uLight, uSide, uPos, uDir, out);
    const Vec3 centre = discCentre(d);
    const Vec3 onDisc = target.center - d * glm::dot(target.center - centre, d);
    const float r = std::min(target.radius, m_sphere.radius);
    const Vec2 q = sampleConcentricDisk(uDir) * r;
    out.ray = Ray();
    out.ray.origin = onDisc + Frame(d).toWorld(Vec3(q.x, q.y, 0.0f));
    out.ray.dir = d;
    const double rr = double(r);
    out.fluxWatts = double(kPi) * rr * rr *
                    glm::max(DVec3(m_scene.directionalLights[static_cast<size_t>(light.directional)].irradiance), DVec3(0.0)) /
                    m_pmf[idx];
    return isFinite(out.ray.origin);
  }
  // The emitting point (as sample()).
  Vec3 pError(0.0f), n(0.0f);
  const Vec3 p = light.pointLight >= 0 ? m_scene.pointLights[static_cast<size_t>(light.pointLight)].position
                                       : pointOn(light, uPos, pError, n);
  const Vec3 toCentre = target.center - p;
  const float dist = glm::length(toCentre);
  if (!(target.radius >= 0.0f) || !(dist > target.radius)) return sample(uLight, uSide, uPos, uDir, out);
  // Uniform in the cone of half-angle asin(R / d): pdf 1 / (2 pi (1 - cos max)).
  const double cosMax = std::sqrt(std::max(0.0, 1.0 - sqr(double(target.radius) / double(dist))));
  const double solidAngle = 2.0 * double(kPi) * (1.0 - cosMax);
  const double cosT = 1.0 - double(uDir.x) * (1.0 - cosMax);
  const double sinT = std::sqrt(std::max(0.0, 1.0 - cosT * cosT));
  const double phi = 2.0 * double(kPi) * double(uDir.y);
  const Vec3 dir = glm::normalize(Frame(toCentre / dist)
                                      .toWorld(Vec3(float(sinT * std::cos(phi)), float(sinT * std::sin(phi)), float(cosT))));
  if (!isFinite(dir) || !isFinite(p)) return false;
  if (light.pointLight >= 0) {
    // Intensity I = flux / (4 pi) into the cone's solid angle.
    out.fluxWatts = light.fluxWatts / (4.0 * double(kPi)) * solidAngle / m_pmf[idx];
    out.ray = Ray();
    out.ray.origin = p;
    out.ray.dir = dir;
    return true;
  }
  // Le A (per side) = flux / (pi sides); the photon carries Le A |cos| / pdf(direction). A
  // two-sided emitter emits the direction from the side it leaves.
  const float cosL = glm::dot(n, dir);
  if (!light.twoSided && !(cosL > 0.0f)) return false;
  const double sides = light.twoSided ? 2.0 : 1.0;
  out.fluxWatts = light.fluxWatts / (double(kPi) * sides) * double(std::fabs(cosL)) * solidAngle / m_pmf[idx];
  out.ray = spawnRay(p, pError, cosL >= 0.0f ? n : -n, dir);
  return true;
}

}  // namespace voxcone

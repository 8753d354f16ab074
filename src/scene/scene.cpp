#include "voxcone/scene/scene.h"

#include "voxcone/scene/bsdf.h"

#include "voxcone/core/error.h"
#include "voxcone/core/sampling.h"

#include <nlohmann/json.hpp>

namespace voxcone {

void RenderSettings::validate() const {
  if (width < 1 || height < 1 || width > 32768 || height > 32768)
    throw SettingsError("resolution must be between 1x1 and 32768x32768, got " + std::to_string(width) + "x" +
                        std::to_string(height));
  if (spp < 1) throw SettingsError("spp must be >= 1, got " + std::to_string(spp));
  if (maxDepth < 1 || maxDepth > 1024) throw SettingsError("max depth must be in [1, 1024], got " + std::to_string(maxDepth));
}

float Scene::triangleArea(uint32_t t) const {
  const UVec3& tri = triangles[t];
  return 0.5f * glm::length(glm::cross(positions[tri.y] - positions[tri.x], positions[tri.z] - positions[tri.x]));
}

void Scene::finalize() {
  for (Material& m : materials) prepareMaterial(m);
  m_bounds = Bounds3();
  for (const Vec3& p : positions) m_bounds.extend(p);

  // Lights: emissive triangles then point lights (the bounded lights, in the light tree), then
  // directional lights and the environment.
  m_emissiveTris.clear();
  m_emissiveArea.clear();
  m_emissiveNormal.clear();
  m_triLightIndex.assign(triangles.size(), -1);
  std::vector<LightBounds> bounded;
  for (uint32_t t = 0; t < triangles.size(); ++t) {
    const Material& m = materials[triMaterial[t]];
    if (!m.isEmissive()) continue;
    const float area = triangleArea(t);
    if (!(area > 0.0f)) continue;
    // Flux of a Lambertian emitter: pi * L * A per side.
    const float flux = kPi * luminance(m.emission) * area * (m.twoSidedEmission ? 2.0f : 1.0f);
    if (!(flux > 0.0f)) continue;
    m_triLightIndex[t] = static_cast<int32_t>(m_emissiveTris.size());
    m_emissiveTris.push_back(t);
    const UVec3& tri = triangles[t];
    const Vec3 cr = glm::cross(positions[tri.y] - positions[tri.x], positions[tri.z] - positions[tri.x]);
    m_emissiveArea.push_back(area);
    m_emissiveNormal.push_back(cr / (2.0f * area));
    LightBounds lb;
    lb.bounds = Bounds3(positions[tri.x], positions[tri.y]);
    lb.bounds.extend(positions[tri.z]);
    lb.w = m_emissiveNormal.back();
    lb.phi = flux;
    lb.twoSided = m.twoSidedEmission;
    bounded.push_back(lb);
  }
  for (const PointLight& pl : pointLights) {
    LightBounds lb;
    lb.bounds = Bounds3(pl.position, pl.position);
    lb.phi = 4.0f * kPi * std::max(0.0f, luminance(pl.intensity));
    lb.cosTheta_o = -1.0f;  // every direction
    bounded.push_back(lb);
  }
  // The bounded lights by power alone (render.lightTree false) and by the tree.
  double boundedTotal = 0.0;
  for (const LightBounds& lb : bounded) boundedTotal += lb.phi;
  m_boundedCdf.resize(bounded.size());
  m_boundedPmf.resize(bounded.size());
  double acc = 0.0;
  for (size_t i = 0; i < bounded.size(); ++i) {
    acc += bounded[i].phi;
    m_boundedPmf[i] = boundedTotal > 0.0 ? static_cast<float>(bounded[i].phi / boundedTotal) : 0.0f;
    m_boundedCdf[i] = boundedTotal > 0.0 ? static_cast<float>(acc / boundedTotal) : 0.0f;
  }
  if (!m_boundedCdf.empty()) m_boundedCdf.back() = 1.0f;
  m_tree = LightTree(bounded);

  // The groups: the bounded lights together, each directional light (the flux through the
  // bounding sphere's cross-section) and the environment (the flux through a disc of radius R
  // facing each direction, pi R^2 times the radiance's integral over the sphere, pbrt-v4's
  // ImageInfiniteLight::Phi).
  std::vector<double> power;
  m_hasBounded = !bounded.empty();
  if (m_hasBounded) power.push_back(boundedTotal);
  const float radius = boundingSphere().radius;
  for (const DirectionalLight& dl : directionalLights)
    power.push_back(kPi * radius * radius * std::max(0.0f, luminance(dl.irradiance)));
  if (environment) power.push_back(kPi * radius * radius * std::max(0.0f, luminance(environment->integral())));
  m_lightCount = bounded.size() + directionalLights.size() + (environment ? 1 : 0);

  double total = 0.0;
  for (double p : power) total += p;
  m_totalPower = static_cast<float>(total);
  m_groupCdf.resize(power.size());
  m_groupPmf.resize(power.size());
  acc = 0.0;
  for (size_t i = 0; i < power.size(); ++i) {
    acc += power[i];
    m_groupPmf[i] = total > 0.0 ? static_cast<float>(power[i] / total) : 0.0f;
    m_groupCdf[i] = total > 0.0 ? static_cast<float>(acc / total) : 0.0f;
  }
  if (!m_groupCdf.empty()) m_groupCdf.back() = 1.0f;
}

Sphere Scene::boundingSphere() const {
  Sphere s;
  if (m_bounds.empty()) return s;
  s.center = m_bounds.center();
  s.radius = 0.5f * glm::length(m_bounds.diagonal());
  return s;
}

SurfaceHit Scene::surfaceAt(uint32_t triangle, float b1, float b2) const {
  SurfaceHit h;
  const UVec3& tri = triangles[triangle];
  const Vec3& p0 = positions[tri.x];
  h.position = barycentricPoint(p0, positions[tri.y], positions[tri.z], 1.0f - b1 - b2, b1, b2, h.positionError);
  h.triangle = triangle;
  h.material = triMaterial[triangle];
  h.geomNormal = glm::normalize(glm::cross(positions[tri.y] - p0, positions[tri.z] - p0));
  h.shadingNormal = h.geomNormal;
  if (!normals.empty() && shapes[triShape[triangle]].smoothNormals) {
    const Vec3 n = (1.0f - b1 - b2) * normals[tri.x] + b1 * normals[tri.y] + b2 * normals[tri.z];
    const float len = glm::length(n);
    if (len > 0.0f && std::isfinite(len)) {
      h.shadingNormal = n / len;
      // Keep the shading normal on the geometric normal's side (winding decides the front).
      if (glm::dot(h.shadingNormal, h.geomNormal) < 0.0f) h.shadingNormal = -h.shadingNormal;
    }
  }
  if (!uvs.empty()) h.uv = (1.0f - b1 - b2) * uvs[tri.x] + b1 * uvs[tri.y] + b2 * uvs[tri.z];
  return h;
}

Vec3 Scene::emitted(const SurfaceHit& hit, const Vec3& w) const {
  const Material& m = materials[hit.material];
  if (!m.isEmissive()) return Vec3(0.0f);
  const float c = glm::dot(hit.geomNormal, w);
  if (c > 0.0f || (m.twoSidedEmission && c < 0.0f)) return m.emission;
  return Vec3(0.0f);
}

bool Scene::chooseGroup(float u, bool withEnvironment, size_t& group, float& pmf, float& rescaled) const {
  if (m_groupCdf.empty()) return false;
  // Choose a group by power (binary search in the CDF), then reuse u within its interval.
  // Without the environment (the last group) u is squeezed below its interval and the choice's
  // probability renormalized.
  const bool dropEnvironment = environment && !withEnvironment;
  const size_t count = m_groupCdf.size() - (dropEnvironment ? 1 : 0);
  const float share = dropEnvironment ? (count == 0 ? 0.0f : m_groupCdf[count - 1]) : 1.0f;
  if (!(share > 0.0f)) return false;
  const float uc = std::min(u * share, share * kOneMinusEpsilon);
  group = std::min(
      static_cast<size_t>(std::upper_bound(m_groupCdf.begin(), m_groupCdf.begin() + long(count), uc) - m_groupCdf.begin()),
      count - 1);
  pmf = m_groupPmf[group] / share;
  if (!(pmf > 0.0f)) return false;
  const float cdfBelow = group == 0 ? 0.0f : m_groupCdf[group - 1];
  rescaled = std::clamp((uc - cdfBelow) / m_groupPmf[group], 0.0f, kOneMinusEpsilon);
  return true;
}

LightSample Scene::sampleLight(const Vec3& ref, const Vec2& uChoice, bool withEnvironment, const Vec3* cosineAbout,
                               const Vec3* normal) const {
  LightSample ls;
  size_t group;
  float pmf, ux;
  if (!chooseGroup(uChoice.x, withEnvironment, group, pmf, ux)) return ls;
  size_t idx;  // the light, in lightCount()'s order
  if (m_hasBounded && group == 0) {
    if (render.lightTree) {
      uint32_t light = 0;
      float treePmf = 0.0f;
      if (!m_tree.sample(ref, normal, ux, light, treePmf)) return ls;
      idx = light;
      pmf *= treePmf;
    } else {
      idx = std::min(static_cast<size_t>(std::upper_bound(m_boundedCdf.begin(), m_boundedCdf.end(), ux) - m_boundedCdf.begin()),
                     m_boundedCdf.size() - 1);
      const float below = idx == 0 ? 0.0f : m_boundedCdf[idx - 1];
      if (!(m_boundedPmf[idx] > 0.0f)) return ls;
      ux = std::clamp((ux - below) / m_boundedPmf[idx], 0.0f, kOneMinusEpsilon);
      pmf *= m_boundedPmf[idx];
    }
  } else {
    idx = m_boundedPmf.size() + group - (m_hasBounded ? 1 : 0);
  }
  return sampleChosen(ref, idx, pmf, Vec2(ux, uChoice.y), cosineAbout);
}

int Scene::sampleLights(const Vec3& ref, const Vec2& uChoice, bool withEnvironment, const Vec3* cosineAbout,
                        const Vec3* normal, LightSample* out) const {
  if (!splitting()) {
    out[0] = sampleLight(ref, uChoice, withEnvironment, cosineAbout, normal);
    return 1;
  }
  size_t group;
  float pmf, ux;
  if (!chooseGroup(uChoice.x, withEnvironment, group, pmf, ux)) {
    out[0] = LightSample();
    return 1;
  }
  if (!(m_hasBounded && group == 0)) {
    out[0] = sampleChosen(ref, m_boundedPmf.size() + group - (m_hasBounded ? 1 : 0), pmf, Vec2(ux, uChoice.y), cosineAbout);
    return 1;
  }
  LightTree::Choice choices[LightTree::kMaxChoices];
  const int n = m_tree.sampleSplit(ref, normal, ux, splitAngle(), choices);
  for (int i = 0; i < n; ++i)
    out[i] = sampleChosen(ref, choices[i].light, pmf * choices[i].pmf, Vec2(choices[i].u, uChoice.y), cosineAbout);
  return n;
}

LightSample Scene::sampleChosen(const Vec3& ref, size_t idx, float pmf, const Vec2& u, const Vec3* cosineAbout) const {
  LightSample ls;
  if (!(pmf > 0.0f)) return ls;
  if (idx < m_emissiveTris.size()) {
    // Uniform point on the emissive triangle, converted to a solid-angle density at ref.
    const uint32_t t = m_emissiveTris[idx];
    const UVec3& tri = triangles[t];
    const Vec2 b = sampleUniformTriangle(u);
    const Vec3& p0 = positions[tri.x];
    const Vec3& p1 = positions[tri.y];
    const Vec3& p2 = positions[tri.z];
    const Vec3 p = barycentricPoint(p0, p1, p2, 1.0f - b.x - b.y, b.x, b.y, ls.lightPosError);
    const float area = m_emissiveArea[idx];
    const Vec3& n = m_emissiveNormal[idx];
    const Vec3 d = p - ref;
    const float dist2 = glm::dot(d, d);
    if (!(dist2 > 0.0f)) return ls;
    const float dist = std::sqrt(dist2);
    ls.wi = d / dist;
    const float cosL = -glm::dot(n, ls.wi);
    const Material& m = materials[triMaterial[t]];
    if (!(cosL > 0.0f) && !(m.twoSidedEmission && cosL < 0.0f)) return ls;
    ls.radiance = m.emission;
    ls.lightPos = p;
    ls.lightNormal = n;
    ls.distance = dist;
    ls.pdf = pmf * dist2 / (std::fabs(cosL) * area);
    return ls;
  }
  const size_t delta = idx - m_emissiveTris.size();
  if (environment && idx + 1 == m_lightCount) {
    ls = sampleEnvironment(ref, u, cosineAbout);
    ls.pdf *= pmf;
    return ls;
  }
  if (delta >= pointLights.size()) {
    // Directional: from -direction, its lightPos beyond the scene's bounding sphere (twice the
    // farthest the sphere reaches from ref), so that the shadow ray crosses the whole scene.
    const DirectionalLight& dl = directionalLights[delta - pointLights.size()];
    const Sphere s = boundingSphere();
    ls.distance = 2.0f * (glm::length(ref - s.center) + s.radius) + 1.0f;
    if (dl.isDelta()) {
      ls.wi = -dl.direction;
      ls.radiance = dl.irradiance;
      ls.pdf = pmf;
      ls.delta = true;
    } else {
      // Uniform in the disc's cone: pdf 1 / (2 pi (1 - cos theta)).
      ls.wi = glm::normalize(Frame(-dl.direction).toWorld(sampleUniformCone(u, dl.oneMinusCos())));
      ls.radiance = dl.radiance();
      ls.pdf = pmf / dl.solidAngle();
    }
    ls.lightPos = ref + ls.wi * ls.distance;
    return ls;
  }
  const PointLight& pl = pointLights[delta];
  const Vec3 d = pl.position - ref;
  const float dist2 = glm::dot(d, d);
  if (!(dist2 > 0.0f)) return ls;
  ls.distance = std::sqrt(dist2);
  ls.wi = d / ls.distance;
  ls.radiance = pl.intensity / dist2;
  ls.lightPos = pl.position;
  ls.pdf = pmf;
  ls.delta = true;
  return ls;
}

LightSample Scene::sampleEnvironment(const Vec3& ref, const Vec2& u, const Vec3* cosineAbout) const {
  // A direction from the environment's own sampler, its lightPos beyond the bounding sphere as
  // a directional light's.
  LightSample ls;
  if (!environment) return ls;
  float pdfDir = 0.0f;
  Vec3 wi;
  if (cosineAbout && environment->isConstant()) {
    // Three quarters cosine-weighted, a quarter uniform (the constant's own sampler) so that
    // directions below the surface (transmission) keep a density. Against cosine sampling
    // alone (zero variance for an unshadowed diffuse point) a sample's weight is at most 4/3
    // of it; the share is not tuned on a scene.
    constexpr float kCosineShare = 0.75f;
    if (u.x < kCosineShare) {
      const Vec2 uc(std::min(u.x / kCosineShare, kOneMinusEpsilon), u.y);
      wi = glm::normalize(Frame(*cosineAbout).toWorld(sampleCosineHemisphere(uc)));
    } else {
      const Vec2 ue(std::min((u.x - kCosineShare) / (1.0f - kCosineShare), kOneMinusEpsilon), u.y);
      wi = environment->sample(ue, pdfDir);
    }
    pdfDir = (1.0f - kCosineShare) * environment->pdf(wi) + kCosineShare * cosineHemispherePdf(glm::dot(wi, *cosineAbout));
  } else {
    wi = environment->sample(u, pdfDir);
  }
  if (!(pdfDir > 0.0f)) return ls;
  const Sphere s = boundingSphere();
  ls.distance = 2.0f * (glm::length(ref - s.center) + s.radius) + 1.0f;
  ls.wi = wi;
  ls.radiance = environment->radiance(wi);
  ls.lightPos = ref + wi * ls.distance;
  ls.pdf = pdfDir;
  return ls;
}

Vec3 Scene::escaped(const Vec3& dir) const {
  Vec3 L = escapedSky(dir);
  for (const DirectionalLight& dl : directionalLights)
    if (dl.seenAlong(dir)) L += dl.radiance();
  return L;
}

Vec3 Scene::escapedMis(const Vec3& dir, float bsdfPdf) const {
  Vec3 L = environment ? environment->radiance(dir) * powerHeuristic(bsdfPdf, escapedPdf(dir)) : Vec3(0.0f);
  const size_t first = m_hasBounded ? 1 : 0;
  for (size_t i = 0; i < directionalLights.size(); ++i) {
    const DirectionalLight& dl = directionalLights[i];
    if (dl.seenAlong(dir)) L += dl.radiance() * powerHeuristic(bsdfPdf, m_groupPmf[first + i] / dl.solidAngle());
  }
  return L;
}

float Scene::lightChoicePmf(const Vec3& ref, const Vec3* normal, size_t light) const {
  if (light >= m_lightCount) return 0.0f;
  const size_t bounded = m_boundedPmf.size();
  if (light >= bounded) return m_groupPmf[light - bounded + (m_hasBounded ? 1 : 0)];
  if (!render.lightTree) return m_groupPmf[0] * m_boundedPmf[light];
  return m_groupPmf[0] *
         (splitting() ? m_tree.pmfSplit(ref, normal, uint32_t(light), splitAngle()) : m_tree.pmf(ref, normal, uint32_t(light)));
}

float Scene::lightPdf(const Vec3& ref, const Vec3* normal, uint32_t triangle, const Vec3& lightPos,
                      const Vec3& lightNormal) const {
  if (m_triLightIndex.empty()) return 0.0f;
  const int32_t li = m_triLightIndex[triangle];
  if (li < 0) return 0.0f;
  const Vec3 d = lightPos - ref;
  const float dist2 = glm::dot(d, d);
  const float cosL = std::fabs(glm::dot(lightNormal, d)) / std::sqrt(dist2);
  if (!(cosL > 0.0f)) return 0.0f;
  return lightChoicePmf(ref, normal, static_cast<size_t>(li)) * dist2 / (cosL * triangleArea(triangle));
}

nlohmann::json Scene::statsJson() const {
  nlohmann::json j;
  j["triangles"] = triangles.size();
  j["vertices"] = positions.size();
  j["shapes"] = shapes.size();
  j["materials"] = materials.size();
  j["emissive_triangles"] = m_emissiveTris.size();
  j["point_lights"] = pointLights.size();
  j["directional_lights"] = directionalLights.size();
  j["environment"] = environment ? (environment->isConstant() ? "constant" : "map") : "none";
  j["bounds_min"] = {m_bounds.lo.x, m_bounds.lo.y, m_bounds.lo.z};
  j["bounds_max"] = {m_bounds.hi.x, m_bounds.hi.y, m_bounds.hi.z};
  return j;
}

}  // namespace voxcone

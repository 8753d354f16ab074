/// \file mitsuba_shapes.cpp
/// Mitsuba 3 shapes (meshes, rectangles, cubes, spheres ...) and emitters as voxcone geometry and
/// lights.

#include "mitsuba_loader_impl.h"

namespace voxcone {
namespace mitsuba_xml {

uint32_t MitsubaLoader::shapeMaterial(const Node* bsdf, const Vec3& radiance) {
  Material m;
  if (bsdf) {
    m = bsdfMaterial(*bsdf);
  } else {
    m.type = MaterialType::Lambertian;
    m.albedo = Vec3(0.5f);
    m.twoSided = false;
    m.name = "default-diffuse";
  }
  m.emission = radiance;
  const auto key = std::make_pair(bsdf ? bsdf->xml.internal_object() : nullptr, std::array<float, 3>{radiance.x, radiance.y, radiance.z});
  const auto it = m_shapeMaterials.find(key);
  if (it != m_shapeMaterials.end()) return it->second;
  // A BSDF used with two radiances becomes two materials: name the later ones apart.
  std::string name = m.name;
  for (int k = 2; m_materialNames.count(name); ++k) name = m.name + "#" + std::to_string(k);
  m.name = name;
  m_materialNames.insert(name);
  m_scene.materials.push_back(m);
  const uint32_t idx = uint32_t(m_scene.materials.size() - 1);
  m_shapeMaterials.emplace(key, idx);
  return idx;
}

std::vector<Vec3> MitsubaLoader::angleWeightedNormals(const std::vector<Vec3>& pos, const std::vector<UVec3>& tris) {
  std::vector<DVec3> acc(pos.size(), DVec3(0.0));
  for (const UVec3& t : tris) {
    const DVec3 v[3] = {DVec3(pos[t.x]), DVec3(pos[t.y]), DVec3(pos[t.z])};
    const DVec3 c = glm::cross(v[1] - v[0], v[2] - v[0]);
    const double len = glm::length(c);
    if (!(len > 0.0)) continue;
    const DVec3 n = c / len;
    for (int j = 0; j < 3; ++j) {
      const DVec3 a = glm::normalize(v[(j + 1) % 3] - v[j]), b = glm::normalize(v[(j + 2) % 3] - v[j]);
      acc[t[j]] += n * std::acos(std::clamp(glm::dot(a, b), -1.0, 1.0));
    }
  }
  std::vector<Vec3> out(pos.size());
  for (size_t i = 0; i < pos.size(); ++i) {
    const double len = glm::length(acc[i]);
    out[i] = len > 0.0 ? Vec3(acc[i] / len) : Vec3(0.0f);
  }
  return out;
}

void MitsubaLoader::parseShape(const Node& n) {
  allowAttrs(n, {"type", "id", "name"});
  Props p(*this, n);
  const std::string& type = p.type();
  const std::string name = hasAttr(n, "id") ? attr(n, "id") : type + std::to_string(m_scene.shapes.size());
  const glm::dmat4 xf = p.getTransform("to_world");
  const glm::dmat3 lin(xf);
  const glm::dmat3 nxf = glm::transpose(glm::inverse(lin));
  if (!(std::abs(glm::determinant(lin)) > 0.0)) fail(n, "to_world is singular");
  const bool flip = p.getBool("flip_normals", false);
  std::vector<Vec3> pos, nrm;
  std::vector<Vec2> uvs;
  std::vector<UVec3> tris;
  auto place = [&](const DVec3& v) { return toFloat(n, DVec3(xf * glm::dvec4(v, 1.0))); };
  // Analytic shapes (rectangle, disk, sphere): Mitsuba's normal is the transformed local one
  // (inverse transpose), so a mirroring to_world keeps them facing where it says.
  auto orientAnalytic = [&](const DVec3& localNormal) {
    if (tris.empty()) return;
    const UVec3& t = tris[0];
    const Vec3 gn = glm::cross(pos[t.y] - pos[t.x], pos[t.z] - pos[t.x]);
    const DVec3 want = nxf * localNormal;
    if (glm::dot(DVec3(gn), want) < 0.0)
      for (UVec3& tr : tris) std::swap(tr.y, tr.z);
  };
  if (type == "obj" || type == "ply") {
    fs::path file = p.getString("filename", "", true);
    if (file.is_relative()) file = fs::path(n.file->dir) / file;
    TriangleMesh mesh;
    m_scene.inputFiles.push_back(file.string());
    try {
      mesh = type == "obj" ? loadObj(file.string()) : loadPly(file.string());
    } catch (const Error& e) {
      fail(n, e.what());
    }
    if (mesh.triangles.empty()) fail(n, "mesh " + file.string() + " has no triangles");
    const bool faceNormals = p.getBool("face_normals", false);
    // Mitsuba flips v by default, its bitmaps' v = 0 being the top row; voxcone's is the bottom
    // row (texture.h), so the file's own coordinates are voxcone's unless told not to flip.
    const bool flipTex = p.getBool("flip_tex_coords", true);
    uvs = mesh.uvs;
    if (!flipTex)
      for (Vec2& uv : uvs) uv.y = 1.0f - uv.y;
    for (const Vec3& v : mesh.positions) pos.push_back(place(DVec3(v)));
    tris = mesh.triangles;  // Mitsuba keeps the file's winding under any to_world
    if (!faceNormals) {
      if (!mesh.normals.empty() && xf == glm::dmat4(1.0))
        nrm = mesh.normals;  // as the file has them (a converted scene keeps them bit for bit)
      else if (!mesh.normals.empty())
        for (const Vec3& v : mesh.normals) nrm.push_back(Vec3(glm::normalize(nxf * DVec3(v))));
      else
        nrm = angleWeightedNormals(pos, tris);
    }
  } else if (type == "rectangle") {
    // Mitsuba 3 rectangle: [-1, 1]^2 in the z = 0 plane, normal +z.
    for (const DVec3& v : {DVec3(-1, -1, 0), DVec3(1, -1, 0), DVec3(1, 1, 0), DVec3(-1, 1, 0)}) pos.push_back(place(v));
    tris = {{0, 1, 2}, {0, 2, 3}};
    // Mitsuba's uv = ((x + 1) / 2, (y + 1) / 2) with v = 0 its bitmaps' top row: voxcone's v
    // (the bottom row at 0) is one minus it.
    uvs = {Vec2(0.0f, 1.0f), Vec2(1.0f, 1.0f), Vec2(1.0f, 0.0f), Vec2(0.0f, 0.0f)};
    orientAnalytic(DVec3(0, 0, 1));
  } else if (type == "disk") {
    // Mitsuba 3 disk: the unit disk in the z = 0 plane, normal +z; a fan of kMitsubaDiskSegments.
    pos.push_back(place(DVec3(0.0)));
    for (int i = 0; i < kMitsubaDiskSegments; ++i) {
      const double a = 2.0 * 3.14159265358979323846 * i / kMitsubaDiskSegments;
      pos.push_back(place(DVec3(std::cos(a), std::sin(a), 0.0)));
      tris.push_back({0u, uint32_t(1 + i), uint32_t(1 + (i + 1) % kMitsubaDiskSegments)});
    }
    orientAnalytic(DVec3(0, 0, 1));
  } else if (type == "cube") {
    // Mitsuba 3 cube: [-1, 1]^3, 6 faces of 4 vertices each, normals outward.
    for (int axis = 0; axis < 3; ++axis)
      for (int sgn : {-1, 1}) {
        const uint32_t b = uint32_t(pos.size());
        DVec3 nrmL(0.0), u(0.0), v(0.0);
        nrmL[axis] = sgn;
        u[(axis + 1) % 3] = 1.0;
        v[(axis + 2) % 3] = 1.0;
        if (sgn < 0) std::swap(u, v);  // keeps cross(u, v) = the outward normal
        for (const auto& [a, c] : {std::pair<int, int>{-1, -1}, {1, -1}, {1, 1}, {-1, 1}})
          pos.push_back(place(nrmL + double(a) * u + double(c) * v));
        tris.push_back({b, b + 1, b + 2});
        tris.push_back({b, b + 2, b + 3});
      }
    // Mitsuba's cube is a mesh: its winding stays, as for obj and ply; its vertex normals are
    // its faces' (each face has its own vertices), so face_normals changes nothing.
    p.getBool("face_normals", false);
  } else if (type == "sphere") {
    const Vec3 center = p.getPoint("center", Vec3(0.0f));
    const float radius = p.getFloat("radius", 1.0f, 1e-9f);
    // Mitsuba's sphere refuses non-uniform scales and shears in to_world.
    const double s0 = glm::length(lin[0]), s1 = glm::length(lin[1]), s2 = glm::length(lin[2]);
    const double tol = 1e-5 * std::max({s0, s1, s2});
    if (std::abs(s0 - s1) > tol || std::abs(s0 - s2) > tol || std::abs(glm::dot(lin[0], lin[1])) > tol * s0 ||
        std::abs(glm::dot(lin[0], lin[2])) > tol * s0 || std::abs(glm::dot(lin[1], lin[2])) > tol * s0)
      fail(n, "a sphere's to_world must be rotation, uniform scale and translation (Mitsuba's rule)");
    std::vector<Vec3> unit;
    detail::makeSphere(Vec3(0.0f), 1.0f, kMitsubaSphereLevel, false, unit, tris);
    for (const Vec3& u : unit) {
      pos.push_back(place(DVec3(center) + double(radius) * DVec3(u)));
      nrm.push_back(Vec3(glm::normalize(nxf * DVec3(u))));
    }
    orientAnalytic(DVec3(unit[tris[0].x] + unit[tris[0].y] + unit[tris[0].z]));
  } else {
    fail(n, "unsupported shape plugin '" + type + "' (voxcone maps obj, ply, rectangle, disk, cube, sphere)");
  }
  if (flip) {
    for (UVec3& t : tris) std::swap(t.y, t.z);
    for (Vec3& v : nrm) v = -v;
  }
  // Its BSDF and area emitter.
  std::vector<Node> bsdfs = p.takeObjects("bsdf");
  std::vector<Node> emitters = p.takeObjects("emitter");
  if (bsdfs.size() > 1) fail(bsdfs[1], "a shape has one BSDF");
  Node bsdf;
  if (!bsdfs.empty()) bsdf = resolve(bsdfs[0], "bsdf");
  Vec3 radiance(0.0f);
  if (emitters.size() > 1) fail(emitters[1], "a shape has one emitter");
  if (!emitters.empty()) {
    const Node e = resolve(emitters[0], "emitter");
    allowAttrs(e, {"type", "id", "name"});
    Props ep(*this, e);
    if (ep.type() != "area") fail(e, "unsupported emitter plugin '" + ep.type() + "' on a shape (voxcone maps area)");
    radiance = ep.getColor("radiance", Vec3(1.0f));
    ep.finish();
    if (isBlack(radiance)) fail(e, "an area emitter with zero radiance");
  }
  p.finish();
  const uint32_t mat = shapeMaterial(bsdf.xml ? &bsdf : nullptr, radiance);
  detail::appendShape(m_scene, name, pos, nrm, uvs, tris, {mat}, !nrm.empty());
}

void MitsubaLoader::parseTopEmitter(const Node& n) {
  allowAttrs(n, {"type", "id", "name"});
  Props p(*this, n);
  if (p.type() == "area") fail(n, "an area emitter must be nested in a <shape>");
  if (p.type() == "directional") {
    // Mitsuba 3's directional emitter: `direction`, or to_world applied to +z; `irradiance`.
    DirectionalLight dl;
    if (p.has("direction") && p.has("to_world")) fail(n, "give direction or to_world, not both");
    const glm::dmat4 xf = p.getTransform("to_world");
    const Vec3 d = p.has("direction") ? p.getPoint("direction", Vec3(0.0f)) : toFloat(n, DVec3(xf * glm::dvec4(0, 0, 1, 0)));
    if (!(glm::length(d) > 0.0f) || !isFinite(glm::normalize(d))) fail(n, "a directional emitter needs a non-zero direction");
    dl.direction = glm::normalize(d);
    dl.irradiance = p.getColor("irradiance", Vec3(1.0f));
    p.finish();
    m_scene.directionalLights.push_back(dl);
    return;
  }
  if (p.type() == "constant" || p.type() == "envmap") {
    if (m_scene.environment) fail(n, "a scene has at most one environment emitter (constant or envmap)");
    if (p.type() == "constant") {
      const Vec3 radiance = p.getColor("radiance", Vec3(1.0f));
      p.finish();
      m_scene.environment = std::make_shared<Environment>(Environment::constant(radiance));
      return;
    }
    // Mitsuba 3's envmap: its map's u = atan2(d.x, -d.z) / (2 pi) in its own frame, a quarter
    // turn about +y from voxcone's (environment.h): voxcone's frame direction (m.z, m.y,
    // -m.x) of Mitsuba's m has the same (u, v). to_world turns Mitsuba's frame into the world.
    fs::path file = p.getString("filename", "", true);
    if (file.is_relative()) file = fs::path(n.file->dir) / file;
    const float scale = p.getFloat("scale", 1.0f, 0.0f);
    const glm::dmat4 xf = p.getTransform("to_world");
    p.finish();
    const glm::mat3 mitsubaToWorld = glm::mat3(glm::dmat3(xf));
    // voxcone's frame in Mitsuba's (the inverse of the map above): +x -> +z, +z -> -x.
    const glm::mat3 voxconeToMitsuba(Vec3(0.0f, 0.0f, 1.0f), Vec3(0.0f, 1.0f, 0.0f), Vec3(-1.0f, 0.0f, 0.0f));
    const glm::mat3 toWorld = mitsubaToWorld * voxconeToMitsuba;
    if (!isRotation(toWorld)) fail(n, "an envmap's to_world must be a rotation");
    m_scene.inputFiles.push_back(file.string());
    try {
      m_scene.environment = std::make_shared<Environment>(loadEnvironmentMap(file.string(), scale, toWorld));
    } catch (const Error& e) {
      fail(n, e.what());
    }
    return;
  }
  if (p.type() != "point")
    fail(n, "unsupported emitter plugin '" + p.type() +
                "' (voxcone maps point, directional, constant, envmap, and area inside a shape)");
  PointLight pl;
  const glm::dmat4 xf = p.getTransform("to_world");
  if (p.has("position") && p.has("to_world")) fail(n, "give position or to_world, not both");
  pl.position = p.has("position") ? p.getPoint("position", Vec3(0.0f)) : toFloat(n, DVec3(xf[3]));
  pl.intensity = p.getColor("intensity", Vec3(1.0f));
  p.finish();
  m_scene.pointLights.push_back(pl);
}

}  // namespace mitsuba_xml
}  // namespace voxcone

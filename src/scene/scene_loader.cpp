// JSON scene loader. Every key is checked: unknown keys and bad values are SceneErrors that
// name the JSON path (pbrt-v4's ParameterDictionary::ReportUnused, applied to JSON).

#include "voxcone/core/error.h"
#include "voxcone/scene/gltf.h"
#include "voxcone/scene/mesh.h"
#include "voxcone/scene/mitsuba.h"
#include "voxcone/scene/scene.h"
#include "scene_build.h"

#include <nlohmann/json.hpp>

#include <glm/gtc/matrix_transform.hpp>

#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <set>
#include <sstream>

namespace voxcone {

namespace {

using nlohmann::json;

/// A JSON object being read: remembers which keys were used so the rest can be reported.
class Reader {
public:
  Reader(const json& j, std::string path, const std::string& file) : m_j(j), m_path(std::move(path)), m_file(file) {
    if (!j.is_object()) fail("expected an object");
  }

  [[noreturn]] void fail(const std::string& what, const std::string& key = "") const {
    throw SceneError(m_file, key.empty() ? m_path : child(key), what);
  }
  std::string child(const std::string& key) const { return m_path.empty() ? key : m_path + "." + key; }
  bool has(const std::string& key) const { return m_j.contains(key); }

  const json& get(const std::string& key) {
    if (!m_j.contains(key)) fail("missing required key", key);
    m_used.insert(key);
    return m_j.at(key);
  }

  float number(const std::string& key, float def, float lo = -kInf, float hi = kInf, bool required = false) {
    if (!has(key)) {
      if (required) fail("missing required key", key);
      return def;
    }
    const json& v = get(key);
    if (!v.is_number()) fail("expected a number", key);
    const double d = v.get<double>();
    if (!std::isfinite(d) || d < lo || d > hi) {
      std::ostringstream os;
      os << "value " << d << " out of range [" << lo << ", " << hi << "]";
      fail(os.str(), key);
    }
    return static_cast<float>(d);
  }

  int64_t integer(const std::string& key, int64_t def, int64_t lo, int64_t hi) {
    if (!has(key)) return def;
    const json& v = get(key);
    if (!v.is_number_integer() && !v.is_number_unsigned()) fail("expected an integer", key);
    const int64_t i = v.is_number_unsigned() ? static_cast<int64_t>(v.get<uint64_t>()) : v.get<int64_t>();
    if (i < lo || i > hi) fail("value " + std::to_string(i) + " out of range [" + std::to_string(lo) + ", " + std::to_string(hi) + "]", key);
    return i;
  }

  bool boolean(const std::string& key, bool def) {
    if (!has(key)) return def;
    const json& v = get(key);
    if (!v.is_boolean()) fail("expected true or false", key);
    return v.get<bool>();
  }

  std::string string(const std::string& key, const std::string& def, bool required = false) {
    if (!has(key)) {
      if (required) fail("missing required key", key);
      return def;
    }
    const json& v = get(key);
    if (!v.is_string()) fail("expected a string", key);
    return v.get<std::string>();
  }

  Vec3 vec3(const std::string& key, const Vec3& def, bool required = false, float lo = -kInf) {
    if (!has(key)) {
      if (required) fail("missing required key", key);
      return def;
    }
    return toVec3(get(key), child(key), lo);
  }

  /// An RGB value given as [r,g,b] or one number (grey).
  /// A colour: one number for all three channels or an array of three, each in [lo, hi]
  /// (reflectances: hi = 1, more would create energy).
  Vec3 rgb(const std::string& key, const Vec3& def, float lo = 0.0f, float hi = kInf) {
    if (!has(key)) return def;
    const json& v = get(key);
    if (v.is_number()) {
      const float f = number(key, 0.0f, lo, hi);
      return Vec3(f);
    }
    return toVec3(v, child(key), lo, hi);
  }

  Vec3 toVec3(const json& v, const std::string& path, float lo = -kInf, float hi = kInf) const {
    if (!v.is_array() || v.size() != 3) throw SceneError(m_file, path, "expected an array of 3 numbers");
    Vec3 r;
    for (int i = 0; i < 3; ++i) {
      if (!v[i].is_number()) throw SceneError(m_file, path, "expected an array of 3 numbers");
      const double d = v[i].get<double>();
      if (!std::isfinite(d)) throw SceneError(m_file, path, "not a finite number");
      if (d < lo || d > hi) {
        std::ostringstream os;
        os << "component " << i << " is " << d << ", out of range [" << lo << ", " << hi << "]";
        throw SceneError(m_file, path, os.str());
      }
      r[i] = static_cast<float>(d);
    }
    return r;
  }

  /// Report keys that were never read.
  void finish() const {
    for (auto it = m_j.begin(); it != m_j.end(); ++it)
      if (!m_used.count(it.key())) fail("unknown key", it.key());
  }

  const std::string& path() const { return m_path; }

private:
  const json& m_j;
  std::string m_path;
  const std::string& m_file;
  std::set<std::string> m_used;
};

/// `albedoTexture` receives `albedo_texture` (a file name as written) of a diffuse material, whose
/// `albedo` then defaults to 1 (a factor on the texture).
Material parseMaterial(Reader& r, const std::string& name, std::string& albedoTexture) {
  Material m;
  m.name = name;
  const std::string type = r.string("type", "", true);
  const bool plastic = type == "plastic" || type == "rough_plastic";
  if (type == "lambertian" || type == "diffuse" || type == "oren_nayar" || plastic) {
    m.type = type == "oren_nayar" ? MaterialType::OrenNayar : MaterialType::Lambertian;
    albedoTexture = r.string("albedo_texture", "");
    if (r.has("albedo_texture") && albedoTexture.empty()) r.fail("expected a file name", "albedo_texture");
    m.albedo = r.rgb("albedo", Vec3(albedoTexture.empty() ? 0.5f : 1.0f), 0.0f, 1.0f);
  }
  if (type == "lambertian" || type == "diffuse") {
    // albedo above
  } else if (type == "oren_nayar") {
    m.sigmaRad = glm::radians(r.number("sigma_deg", 20.0f, 0.0f, 90.0f));
  } else if (plastic) {
    m.type = type == "plastic" ? MaterialType::Plastic : MaterialType::RoughPlastic;
    m.ior = r.number("ior", 1.5f, 1.0001f, 10.0f);
    m.specular = r.rgb("specular", Vec3(1.0f), 0.0f, 1.0f);
    m.coatNonlinear = r.boolean("nonlinear", false);
  } else if (type == "thin_dielectric") {
    m.type = MaterialType::ThinDielectric;
    m.ior = r.number("ior", 1.5f, 1.0001f, 10.0f);
    m.specular = r.rgb("specular", Vec3(1.0f), 0.0f, 1.0f);
  } else if (type == "mirror") {
    m.type = MaterialType::Mirror;
    m.specular = r.rgb("specular", Vec3(1.0f), 0.0f, 1.0f);
  } else if (type == "dielectric" || type == "rough_dielectric") {
    m.type = type == "dielectric" ? MaterialType::Dielectric : MaterialType::RoughDielectric;
    m.ior = r.number("ior", 1.5f, 1.0001f, 10.0f);
    m.specular = r.rgb("specular", Vec3(1.0f), 0.0f, 1.0f);
  } else if (type == "conductor" || type == "rough_conductor") {
    m.type = type == "conductor" ? MaterialType::Conductor : MaterialType::RoughConductor;
    m.eta = r.vec3("eta", Vec3(0.2f), false, 0.0f);
    m.k = r.vec3("k", Vec3(3.0f), false, 0.0f);
    m.specular = r.rgb("specular", Vec3(1.0f), 0.0f, 1.0f);
  } else {
    r.fail("unknown material type '" + type +
               "' (lambertian, oren_nayar, plastic, rough_plastic, mirror, dielectric, rough_dielectric, "
               "thin_dielectric, conductor, rough_conductor)",
           "type");
  }
  if (m.type == MaterialType::RoughConductor || m.type == MaterialType::RoughDielectric ||
      m.type == MaterialType::RoughPlastic) {
    m.roughness = r.number("roughness", 0.1f, 1e-4f, 1.0f);
    const std::string dist = r.string("distribution", "ggx");
    if (dist == "ggx")
      m.distribution = MicrofacetDistribution::GGX;
    else if (dist == "beckmann")
      m.distribution = MicrofacetDistribution::Beckmann;
    else
      r.fail("unknown distribution '" + dist + "' (ggx, beckmann)", "distribution");
  }
  m.emission = r.rgb("emission", Vec3(0.0f));
  m.twoSidedEmission = r.boolean("two_sided_emission", false);
  m.twoSided = r.boolean("two_sided", true);
  r.finish();
  return m;
}

/// Affine transform: scale, then rotation about an axis, then translation.
glm::mat4 parseTransform(Reader& r) {
  glm::mat4 m(1.0f);
  Vec3 scale(1.0f);
  if (r.has("scale")) {
    const json& s = r.get("scale");
    if (s.is_number()) {
      scale = Vec3(r.number("scale", 1.0f));
    } else {
      scale = r.toVec3(s, r.child("scale"));
    }
    if (scale.x == 0.0f || scale.y == 0.0f || scale.z == 0.0f) r.fail("scale must not be zero", "scale");
  }
  const Vec3 translate = r.vec3("translate", Vec3(0.0f));
  const Vec3 axis = r.vec3("rotate_axis", Vec3(0.0f, 1.0f, 0.0f));
  const float angle = r.number("rotate_deg", 0.0f, -360.0f, 360.0f);
  r.finish();
  if (glm::length(axis) == 0.0f) r.fail("rotation axis must not be zero", "rotate_axis");
  m = glm::translate(m, translate);
  m = glm::rotate(m, glm::radians(angle), glm::normalize(axis));
  m = glm::scale(m, scale);
  return m;
}

}  // namespace

namespace detail {

void makeSphere(const Vec3& center, float radius, int level, bool inward, std::vector<Vec3>& pos, std::vector<UVec3>& tris) {
  const float t = (1.0f + std::sqrt(5.0f)) / 2.0f;
  std::vector<Vec3> v = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                         {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  std::vector<UVec3> f = {{0, 11, 5}, {0, 5, 1}, {0, 1, 7}, {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
                          {11, 10, 2}, {10, 7, 6}, {7, 1, 8}, {3, 9, 4}, {3, 4, 2}, {3, 2, 6}, {3, 6, 8},
                          {3, 8, 9}, {4, 9, 5}, {2, 4, 11}, {6, 2, 10}, {8, 6, 7}, {9, 8, 1}};
  for (Vec3& p : v) p = glm::normalize(p);
  for (int l = 0; l < level; ++l) {
    std::vector<UVec3> nf;
    std::map<std::pair<uint32_t, uint32_t>, uint32_t> mid;
    auto midpoint = [&](uint32_t a, uint32_t b) {
      const auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back(glm::normalize(v[a] + v[b]));
      const uint32_t idx = static_cast<uint32_t>(v.size() - 1);
      mid.emplace(key, idx);
      return idx;
    };
    for (const UVec3& tri : f) {
      const uint32_t a = midpoint(tri.x, tri.y), b = midpoint(tri.y, tri.z), c = midpoint(tri.z, tri.x);
      nf.push_back({tri.x, a, c});
      nf.push_back({tri.y, b, a});
      nf.push_back({tri.z, c, b});
      nf.push_back({a, b, c});
    }
    f.swap(nf);
  }
  const uint32_t base = static_cast<uint32_t>(pos.size());
  for (const Vec3& p : v) pos.push_back(center + radius * p);
  for (UVec3 tri : f) {
    if (inward) std::swap(tri.y, tri.z);
    tris.push_back(tri + UVec3(base));
  }
}

}  // namespace detail

namespace {

using detail::makeSphere;

class SceneBuilder {
public:
  SceneBuilder(const std::string& file, const std::string& baseDir) : m_file(file), m_baseDir(baseDir) {
    m_scene.sourcePath = file;
  }

  /// No camera coordinate beyond this (scene_build.h: the float range checks, shared with the
  /// Mitsuba loader).
  static constexpr double kMaxReach = detail::kMaxSceneReach;

  Scene build(const json& root) {
    Reader r(root, "", m_file);
    if (r.has("camera")) parseCamera(Reader(r.get("camera"), "camera", m_file));
    else r.fail("missing required key", "camera");
    if (r.has("render")) parseRender(Reader(r.get("render"), "render", m_file));
    parseMaterials(r.get("materials"));
    const json& shapes = r.get("shapes");
    if (!shapes.is_array()) r.fail("expected an array", "shapes");
    for (size_t i = 0; i < shapes.size(); ++i) parseShape(shapes[i], "shapes[" + std::to_string(i) + "]");
    if (r.has("lights")) {
      const json& lights = r.get("lights");
      if (!lights.is_array()) r.fail("expected an array", "lights");
      for (size_t i = 0; i < lights.size(); ++i) parseLight(lights[i], "lights[" + std::to_string(i) + "]");
    }
    r.finish();
    detail::finishScene(m_scene, m_file);
    return std::move(m_scene);
  }

private:
  void parseCamera(Reader r) {
    const Vec3 pos = r.vec3("position", Vec3(0.0f), true);
    const Vec3 target = r.vec3("target", Vec3(0.0f), true);
    const Vec3 up = r.vec3("up", Vec3(0.0f, 1.0f, 0.0f));
    const float fov = r.number("fov_y_deg", 40.0f, 0.01f, 179.0f);
    r.finish();
    // Beyond the scene's range (checkPrecision) a camera's own vectors overflow float (scaled
    // 1e17, "up is parallel to the view direction" was the error).
    for (const auto& [key, v] : {std::pair<const char*, Vec3>{"position", pos}, {"target", target}})
      if (maxComponent(glm::abs(v)) > float(kMaxReach))
        r.fail("coordinates beyond " + std::to_string(int64_t(kMaxReach)) + " are outside the range voxcone renders in float",
               key);
    // In double: a scene scaled far below the range (1e-40) squared its float distances to zero
    // and said "target equals position"; checkPrecision names the scale instead.
    const DVec3 view = DVec3(target) - DVec3(pos), upD(up);
    if (glm::length(view) == 0.0) r.fail("target equals position", "target");
    if (glm::length(upD) == 0.0 || glm::length(glm::cross(view, upD)) <= 1e-6 * glm::length(view) * glm::length(upD))
      r.fail("up is parallel to the view direction", "up");
    m_scene.camera = Camera(pos, target, up, fov);
  }

  void parseRender(Reader r) {
    RenderSettings& s = m_scene.render;
    s.width = static_cast<int>(r.integer("width", s.width, 1, 32768));
    s.height = static_cast<int>(r.integer("height", s.height, 1, 32768));
    s.spp = static_cast<int>(r.integer("spp", s.spp, 1, 1 << 24));
    s.maxDepth = static_cast<int>(r.integer("max_depth", s.maxDepth, 1, 1024));
    s.seed = static_cast<uint64_t>(r.integer("seed", 0, 0, INT64_MAX));
    s.method = r.string("method", s.method);
    const std::string sampler = r.string("sampler", samplerNames()[size_t(s.sampler)]);
    try {
      s.sampler = samplerKindFromName(sampler);
    } catch (const SettingsError& e) {
      r.fail(e.what(), "sampler");
    }
    const std::string lightSampler = r.string("light_sampler", s.lightTree ? "tree" : "power");
    if (lightSampler != "tree" && lightSampler != "power") r.fail("must be \"tree\" or \"power\", got \"" + lightSampler + "\"", "light_sampler");
    s.lightTree = lightSampler == "tree";
    s.lightSplitDeg = r.number("light_split", s.lightSplitDeg, 0.0f, 90.0f);
    s.photons = static_cast<uint64_t>(r.integer("photons", static_cast<int64_t>(s.photons), 0, int64_t(1) << 36));
    s.causticPhotons =
        static_cast<uint64_t>(r.integer("caustic_photons", static_cast<int64_t>(s.causticPhotons), 0, int64_t(1) << 36));
    r.finish();
  }

  void parseMaterials(const json& mats) {
    if (!mats.is_object()) throw SceneError(m_file, "materials", "expected an object of named materials");
    for (auto it = mats.begin(); it != mats.end(); ++it) {
      Reader r(it.value(), "materials." + it.key(), m_file);
      m_materialIndex[it.key()] = static_cast<uint32_t>(m_scene.materials.size());
      std::string texture;
      Material m = parseMaterial(r, it.key(), texture);
      if (!texture.empty()) {
        std::filesystem::path p(texture);
        if (p.is_relative()) p = std::filesystem::path(m_baseDir) / p;
        m_scene.inputFiles.push_back(p.string());
        try {
          m.albedoTexture = detail::textureIndex(m_scene, p.string());
        } catch (const Error& e) {
          throw SceneError(m_file, "materials." + it.key() + ".albedo_texture", e.what());
        }
      }
      m_scene.materials.push_back(std::move(m));
    }
  }

  uint32_t materialRef(Reader& r, const std::string& key) {
    const std::string name = r.string(key, "", true);
    auto it = m_materialIndex.find(name);
    if (it == m_materialIndex.end()) r.fail("unknown material '" + name + "'", key);
    return it->second;
  }


  void parseShape(const json& j, const std::string& path) {
    Reader r(j, path, m_file);
    const std::string type = r.string("type", "", true);
    const std::string name = r.string("name", type + std::to_string(m_scene.shapes.size()));
    std::vector<Vec3> pos, nrm;
    std::vector<Vec2> uvs;
    std::vector<UVec3> tris;
    std::vector<uint32_t> triMat;
    bool smooth = false;
    if (type == "quad" || type == "triangle") {
      const size_t n = type == "quad" ? 4 : 3;
      const json& verts = r.get("vertices");
      if (!verts.is_array() || verts.size() != n)
        r.fail("expected " + std::to_string(n) + " vertices", "vertices");
      for (size_t i = 0; i < n; ++i) pos.push_back(r.toVec3(verts[i], r.child("vertices") + "[" + std::to_string(i) + "]"));
      // A quad is the triangles (v0,v1,v2) and (v0,v2,v3) (SPEC.md: the split is geometry).
      tris.push_back({0, 1, 2});
      if (n == 4) tris.push_back({0, 2, 3});
      // Texture coordinates: v0 (0, 0), v1 (1, 0), v2 (1, 1), v3 (0, 1).
      uvs = {Vec2(0.0f, 0.0f), Vec2(1.0f, 0.0f), Vec2(1.0f, 1.0f)};
      if (n == 4) uvs.push_back(Vec2(0.0f, 1.0f));
      triMat.push_back(materialRef(r, "material"));
    } else if (type == "sphere") {
      const Vec3 c = r.vec3("center", Vec3(0.0f), true);
      const float radius = r.number("radius", 1.0f, 1e-6f, kInf, true);
      const int level = static_cast<int>(r.integer("subdivisions", 3, 0, 8));
      const bool inward = r.boolean("inward", false);
      makeSphere(c, radius, level, inward, pos, tris);
      triMat.push_back(materialRef(r, "material"));
    } else if (type == "mesh") {
      const std::string file = r.string("file", "", true);
      std::filesystem::path p(file);
      if (p.is_relative()) p = std::filesystem::path(m_baseDir) / p;
      TriangleMesh mesh;
      m_scene.inputFiles.push_back(p.string());
      try {
        mesh = loadMesh(p.string());
      } catch (const Error& e) {
        r.fail(e.what(), "file");
      }
      if (mesh.triangles.empty()) r.fail("mesh '" + p.string() + "' has no triangles", "file");
      glm::mat4 xf(1.0f);
      if (r.has("transform")) {
        Reader tr(r.get("transform"), r.child("transform"), m_file);
        xf = parseTransform(tr);
      }
      smooth = r.boolean("smooth_normals", false);
      if (smooth && mesh.normals.empty()) r.fail("smooth_normals asks for vertex normals but the mesh has none", "smooth_normals");
      const glm::mat3 nxf = glm::transpose(glm::inverse(glm::mat3(xf)));
      pos.reserve(mesh.positions.size());
      for (const Vec3& v : mesh.positions) pos.push_back(Vec3(xf * Vec4(v, 1.0f)));
      if (smooth)
        for (const Vec3& n : mesh.normals) nrm.push_back(glm::normalize(nxf * n));
      tris = std::move(mesh.triangles);
      uvs = std::move(mesh.uvs);
      // Winding flips under a mirroring transform; keep the front side where the file had it.
      if (glm::determinant(glm::mat3(xf)) < 0.0f)
        for (UVec3& t : tris) std::swap(t.y, t.z);
      if (r.has("material")) {
        triMat.push_back(materialRef(r, "material"));
      } else {
        if (mesh.materials.empty()) r.fail("the mesh defines no materials: give 'material'", "material");
        std::vector<uint32_t> fileMats;
        for (const MeshMaterial& mm : mesh.materials) {
          try {
            fileMats.push_back(addMeshMaterial(mm, file, p.parent_path()));
          } catch (const Error& e) {
            r.fail(e.what(), "file");
          }
        }
        triMat.resize(tris.size());
        for (size_t i = 0; i < tris.size(); ++i) {
          const int32_t fm = i < mesh.faceMaterial.size() ? mesh.faceMaterial[i] : -1;
          if (fm < 0 || static_cast<size_t>(fm) >= fileMats.size())
            r.fail("face " + std::to_string(i) + " has no material: give 'material'", "material");
          triMat[i] = fileMats[static_cast<size_t>(fm)];
        }
      }
    } else if (type == "gltf") {
      // Every mesh of a glTF file with its materials (not its cameras and lights).
      std::filesystem::path p(r.string("file", "", true));
      if (p.is_relative()) p = std::filesystem::path(m_baseDir) / p;
      glm::mat4 xf(1.0f);
      if (r.has("transform")) {
        Reader tr(r.get("transform"), r.child("transform"), m_file);
        xf = parseTransform(tr);
      }
      r.finish();
      m_scene.inputFiles.push_back(p.string());
      std::vector<std::string> warnings;
      try {
        appendGltfMeshes(m_scene, p.string(), xf, warnings);
      } catch (const Error& e) {
        r.fail(e.what(), "file");
      }
      for (const std::string& w : warnings) std::cerr << "warning: " << w << "\n";
      return;
    } else {
      r.fail("unknown shape type '" + type + "' (quad, triangle, sphere, mesh, gltf)", "type");
    }
    r.finish();
    detail::appendShape(m_scene, name, pos, nrm, uvs, tris, triMat, smooth);
  }

  /// An MTL material becomes a Lambertian with Kd (and Ke as emission).
  /// With `map_Kd` the albedo is the texture alone (Kd ignored, as pbrt and Blender's importer
  /// take it), the file relative to the OBJ's folder `dir`.
  uint32_t addMeshMaterial(const MeshMaterial& mm, const std::string& file, const std::filesystem::path& dir) {
    Material m;
    m.name = file + ":" + mm.name;
    m.type = MaterialType::Lambertian;
    m.albedo = glm::clamp(mm.kd, Vec3(0.0f), Vec3(1.0f));
    if (!mm.mapKd.empty()) {
      std::filesystem::path t(mm.mapKd);
      if (t.is_relative()) t = dir / t;
      m_scene.inputFiles.push_back(t.string());
      m.albedoTexture = detail::textureIndex(m_scene, t.string());
      m.albedo = Vec3(1.0f);
    }
    m.emission = glm::max(mm.ke, Vec3(0.0f));
    m_scene.materials.push_back(m);
    return static_cast<uint32_t>(m_scene.materials.size() - 1);
  }

  void parseLight(const json& j, const std::string& path) {
    Reader r(j, path, m_file);
    const std::string type = r.string("type", "", true);
    if (type == "directional") {
      DirectionalLight dl;
      const Vec3 d = r.vec3("direction", Vec3(0.0f), true);
      if (!(glm::length(d) > 0.0f) || !isFinite(glm::normalize(d))) r.fail("must be a non-zero vector", "direction");
      dl.direction = glm::normalize(d);
      dl.irradiance = r.rgb("irradiance", Vec3(0.0f));
      // The full angle; 0 a delta light.
      dl.halfAngle = glm::radians(0.5f * r.number("angle_deg", 0.0f, 0.0f, 90.0f));
      r.finish();
      m_scene.directionalLights.push_back(dl);
      return;
    }
    if (type == "environment") {
      if (m_scene.environment) r.fail("a scene has at most one environment light");
      const bool hasFile = r.has("file"), hasRadiance = r.has("radiance");
      if (hasFile == hasRadiance) r.fail("give either 'file' (an equirectangular map) or 'radiance' (a constant sky)");
      if (hasRadiance) {
        const Vec3 radiance = r.rgb("radiance", Vec3(0.0f));
        r.finish();
        m_scene.environment = std::make_shared<Environment>(Environment::constant(radiance));
        return;
      }
      std::filesystem::path p(r.string("file", "", true));
      if (p.is_relative()) p = std::filesystem::path(m_baseDir) / p;
      const float scale = r.number("scale", 1.0f, 0.0f, kInf);
      if (r.has("rotate_deg") && r.has("to_world")) r.fail("give 'rotate_deg' or 'to_world', not both");
      glm::mat3 toWorld = rotationY(r.number("rotate_deg", 0.0f, -360.0f, 360.0f));
      if (r.has("to_world")) {
        const json& m = r.get("to_world");
        if (!m.is_array() || m.size() != 3) r.fail("expected 3 rows of 3 numbers (a rotation)", "to_world");
        for (int row = 0; row < 3; ++row) {
          const Vec3 v = r.toVec3(m[size_t(row)], r.child("to_world"));
          for (int col = 0; col < 3; ++col) toWorld[col][row] = v[col];
        }
        if (!isRotation(toWorld)) r.fail("must be a rotation (orthonormal rows, determinant 1)", "to_world");
      }
      r.finish();
      m_scene.inputFiles.push_back(p.string());
      try {
        m_scene.environment = std::make_shared<Environment>(loadEnvironmentMap(p.string(), scale, toWorld));
      } catch (const Error& e) {
        r.fail(e.what(), "file");
      }
      return;
    }
    if (type != "point")
      r.fail("unknown light type '" + type + "' (point, directional, environment; area lights are emissive shapes)",
             "type");
    PointLight pl;
    pl.position = r.vec3("position", Vec3(0.0f), true);
    pl.intensity = r.rgb("intensity", Vec3(0.0f));
    r.finish();
    m_scene.pointLights.push_back(pl);
  }

  std::string m_file, m_baseDir;
  Scene m_scene;
  std::map<std::string, uint32_t> m_materialIndex;
};

}  // namespace

namespace detail {

void checkScenePrecision(const Scene& scene, const std::string& file) {
  const Bounds3& b = scene.bounds();
  const DVec3 lo(b.lo), hi(b.hi);
  const double extent = std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z});
  const double reach = std::max({std::abs(lo.x), std::abs(lo.y), std::abs(lo.z), std::abs(hi.x), std::abs(hi.y),
                                 std::abs(hi.z)});
  std::ostringstream os;
  os.precision(3);
  if (!(extent >= kMinSceneExtent && extent <= kMaxSceneExtent)) {
    os << "the scene is " << extent << " units across: voxcone renders scenes between " << kMinSceneExtent << " and "
       << kMaxSceneExtent << " across correctly in float (scale it)";
    throw SceneError(file, "shapes", os.str());
  }
  if (reach > kMaxSceneOffset * extent) {
    os << "the scene reaches " << reach << " from the origin but is " << extent
       << " across: beyond " << kMaxSceneOffset << " times its size float positions lose the detail it needs (move it "
       << "near the origin)";
    throw SceneError(file, "shapes", os.str());
  }
}

void appendShape(Scene& scene, const std::string& name, const std::vector<Vec3>& pos, const std::vector<Vec3>& nrm,
                 const std::vector<Vec2>& uvs, const std::vector<UVec3>& tris, const std::vector<uint32_t>& triMat,
                 bool smooth) {
  ShapeInfo info;
  info.name = name;
  info.firstTriangle = static_cast<uint32_t>(scene.triangles.size());
  info.triangleCount = static_cast<uint32_t>(tris.size());
  info.smoothNormals = smooth && !nrm.empty();
  info.hasUvs = !uvs.empty() && uvs.size() == pos.size();
  const uint32_t shapeIdx = static_cast<uint32_t>(scene.shapes.size());
  const uint32_t base = static_cast<uint32_t>(scene.positions.size());
  // Normals and texture coordinates: every vertex has one once any shape has them (zeros
  // where a shape has none).
  if (info.smoothNormals && scene.normals.size() < scene.positions.size())
    scene.normals.resize(scene.positions.size(), Vec3(0.0f));
  if (info.hasUvs && scene.uvs.size() < scene.positions.size()) scene.uvs.resize(scene.positions.size(), Vec2(0.0f));
  scene.positions.insert(scene.positions.end(), pos.begin(), pos.end());
  if (info.smoothNormals)
    scene.normals.insert(scene.normals.end(), nrm.begin(), nrm.end());
  else if (!scene.normals.empty())
    scene.normals.resize(scene.positions.size(), Vec3(0.0f));
  if (info.hasUvs)
    scene.uvs.insert(scene.uvs.end(), uvs.begin(), uvs.end());
  else if (!scene.uvs.empty())
    scene.uvs.resize(scene.positions.size(), Vec2(0.0f));
  scene.triangles.reserve(scene.triangles.size() + tris.size());
  for (size_t i = 0; i < tris.size(); ++i) {
    scene.triangles.push_back(tris[i] + UVec3(base));
    scene.triMaterial.push_back(triMat.size() == 1 ? triMat[0] : triMat[i]);
    scene.triShape.push_back(shapeIdx);
  }
  scene.shapes.push_back(info);
}

int32_t textureIndex(Scene& scene, const std::string& path) {
  for (size_t i = 0; i < scene.textures.size(); ++i)
    if (scene.textures[i]->file == path) return int32_t(i);
  scene.textures.push_back(std::make_shared<const Texture>(loadTexture(path)));
  return int32_t(scene.textures.size() - 1);
}

void finishScene(Scene& scene, const std::string& file) {
  if (scene.triangles.empty()) throw SceneError(file, "shapes", "the scene has no triangles");
  // A texture needs texture coordinates: a shape without them would take one texel everywhere.
  for (size_t t = 0; t < scene.triangles.size(); ++t) {
    const Material& m = scene.materials[scene.triMaterial[t]];
    const ShapeInfo& shape = scene.shapes[scene.triShape[t]];
    if (m.albedoTexture >= 0 && !shape.hasUvs)
      throw SceneError(file, "shapes", "shape '" + shape.name + "' has material '" + m.name +
                                           "' with a texture but no texture coordinates");
  }
  scene.finalize();
  checkScenePrecision(scene, file);
  if (!scene.hasLights()) throw SceneError(file, "", "the scene has no light (no emissive surface, no point, directional or environment light)");
}

}  // namespace detail

Scene parseScene(const std::string& jsonText, const std::string& origin, const std::string& baseDir) {
  json root;
  try {
    root = json::parse(jsonText);
  } catch (const json::parse_error& e) {
    std::string msg = e.what();
    // nlohmann's message: "[json.exception.parse_error.101] parse error at line 3, column 5: ..."
    const auto pos = msg.find("parse error");
    throw SceneError(origin, "", "invalid JSON: " + (pos == std::string::npos ? msg : msg.substr(pos)));
  } catch (const json::out_of_range& e) {
    // "[json.exception.out_of_range.406] number overflow parsing '1e999'": no position, so the
    // number's first occurrence in the text gives the line.
    const std::string msg = e.what();
    const auto q0 = msg.find('\''), q1 = msg.rfind('\'');
    std::string where;
    if (q0 != std::string::npos && q1 > q0 + 1) {
      const std::string token = msg.substr(q0 + 1, q1 - q0 - 1);
      const auto at = jsonText.find(token);
      if (at != std::string::npos)
        where = " at line " + std::to_string(1 + std::count(jsonText.begin(), jsonText.begin() + long(at), '\n'));
      where += ": " + token.substr(0, 32);
    }
    throw SceneError(origin, "", "invalid JSON: a number too large for a double" + where);
  }
  return SceneBuilder(origin, baseDir).build(root);
}

Scene loadScene(const std::string& path) { return loadScene(path, {}); }

Scene loadScene(const std::string& path, const std::map<std::string, std::string>& parameters) {
  if (isMitsubaScenePath(path)) return loadMitsubaScene(path, parameters);
  if (isGltfScenePath(path)) {
    if (!parameters.empty())
      throw SceneError(path, "", "-D " + parameters.begin()->first + "=...: parameters apply to Mitsuba XML scenes only");
    return loadGltfScene(path);
  }
  if (!parameters.empty())
    throw SceneError(path, "", "-D " + parameters.begin()->first + "=...: parameters apply to Mitsuba XML scenes only");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw SceneError(path, "", "cannot open scene file");
  std::ostringstream ss;
  ss << in.rdbuf();
  const std::string dir = std::filesystem::path(path).parent_path().string();
  Scene scene = parseScene(ss.str(), path, dir.empty() ? "." : dir);
  scene.inputFiles.insert(scene.inputFiles.begin(), path);
  return scene;
}

}  // namespace voxcone

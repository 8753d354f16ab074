// Writing a loaded Scene as voxcone JSON or Mitsuba 3 XML (`voxcone convert`). Both formats
// get the geometry the same way: one binary PLY file per run of a shape's triangles that share
// a material, so that positions survive bit for bit and any shape (quad, sphere, OBJ with MTL
// materials, a Mitsuba analytic shape already tessellated) converts alike.

#include "voxcone/core/error.h"
#include "voxcone/scene/mitsuba.h"

#include <nlohmann/json.hpp>

#include <charconv>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

namespace voxcone {
namespace {

namespace fs = std::filesystem;

/// The shortest decimal that reads back as the same float ("0.725", not 0.7250000238...).
std::string floatText(float v) {
  char buf[32];
  const auto res = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, res.ptr);
}
/// floatText as a JSON number.
double clean(float v) { return std::strtod(floatText(v).c_str(), nullptr); }
nlohmann::json cleanVec(const Vec3& v) { return {clean(v.x), clean(v.y), clean(v.z)}; }
std::string vecText(const Vec3& v) { return floatText(v.x) + ", " + floatText(v.y) + ", " + floatText(v.z); }

std::string xmlEscape(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

/// A file-name-safe version of a shape's name.
std::string safeName(const std::string& s) {
  std::string out;
  for (char c : s) out += std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' ? c : '_';
  return out.empty() ? "shape" : out.substr(0, 48);
}

/// One mesh file: triangles [first, first + count) of one shape, all of material `material`.
struct MeshRun {
  std::string name;      ///< the shape's name (with #k for later runs of one shape)
  std::string relPath;   ///< relative to the scene file
  uint32_t material = 0;
  bool smooth = false;
  bool uvs = false;      ///< with texture coordinates (u v)
};

/// Binary little-endian PLY of triangles [first, first + count): float x y z (nx ny nz) (u v),
/// uchar int vertex_indices; vertices renumbered in order of first use.
void writePly(const Scene& scene, uint32_t first, uint32_t count, bool smooth, bool uvs, const fs::path& path) {
  static_assert(sizeof(float) == 4 && sizeof(int32_t) == 4, "PLY float and int are 4 bytes");
  const uint16_t probe = 1;
  unsigned char low;
  std::memcpy(&low, &probe, 1);
  if (low != 1) throw Error("writing PLY: this build writes little-endian files on little-endian machines only");
  std::map<uint32_t, uint32_t> remap;
  std::vector<uint32_t> order;
  std::vector<UVec3> tris;
  for (uint32_t t = first; t < first + count; ++t) {
    UVec3 local;
    for (int k = 0; k < 3; ++k) {
      const uint32_t v = scene.triangles[t][k];
      const auto [it, fresh] = remap.emplace(v, uint32_t(order.size()));
      if (fresh) order.push_back(v);
      local[k] = it->second;
    }
    tris.push_back(local);
  }
  std::ostringstream head;
  head << "ply\nformat binary_little_endian 1.0\ncomment written by voxcone convert\nelement vertex " << order.size()
       << "\nproperty float x\nproperty float y\nproperty float z\n";
  if (smooth) head << "property float nx\nproperty float ny\nproperty float nz\n";
  if (uvs) head << "property float u\nproperty float v\n";
  head << "element face " << tris.size() << "\nproperty list uchar int vertex_indices\nend_header\n";
  std::string bytes = head.str();
  const auto put = [&](const void* p, size_t n) { bytes.append(static_cast<const char*>(p), n); };
  for (uint32_t v : order) {
    put(&scene.positions[v], 12);
    if (smooth) put(&scene.normals[v], 12);
    if (uvs) put(&scene.uvs[v], 8);
  }
  for (const UVec3& t : tris) {
    const unsigned char three = 3;
    put(&three, 1);
    const int32_t idx[3] = {int32_t(t.x), int32_t(t.y), int32_t(t.z)};
    put(idx, 12);
  }
  std::ofstream out(path, std::ios::binary);
  out.write(bytes.data(), std::streamsize(bytes.size()));
  if (!out) throw Error("cannot write " + path.string());
}

/// Split every shape into runs of one material and write each as a PLY in <stem>_meshes/.
std::vector<MeshRun> writeMeshes(const Scene& scene, const fs::path& scenePath) {
  const std::string folder = scenePath.stem().string() + "_meshes";
  const fs::path dir = scenePath.parent_path() / folder;
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw Error("cannot create " + dir.string() + ": " + ec.message());
  std::vector<MeshRun> runs;
  for (const ShapeInfo& s : scene.shapes) {
    uint32_t t = s.firstTriangle;
    const uint32_t end = s.firstTriangle + s.triangleCount;
    for (int part = 1; t < end; ++part) {
      uint32_t u = t + 1;
      while (u < end && scene.triMaterial[u] == scene.triMaterial[t]) ++u;
      MeshRun r;
      r.name = part == 1 ? s.name : s.name + "#" + std::to_string(part);
      char index[16];
      std::snprintf(index, sizeof index, "%03zu", runs.size());
      const std::string file = std::string(index) + "_" + safeName(r.name) + ".ply";
      r.relPath = folder + "/" + file;
      r.material = scene.triMaterial[t];
      r.smooth = s.smoothNormals && !scene.normals.empty();
      r.uvs = s.hasUvs && !scene.uvs.empty();
      writePly(scene, t, u - t, r.smooth, r.uvs, dir / file);
      runs.push_back(r);
      t = u;
    }
  }
  return runs;
}

/// Unique material names (mesh materials of two files may share one).
std::vector<std::string> materialNames(const Scene& scene) {
  std::vector<std::string> names;
  std::set<std::string> seen;
  for (const Material& m : scene.materials) {
    std::string n = m.name.empty() ? "material" : m.name;
    for (int k = 2; seen.count(n); ++k) n = m.name + "#" + std::to_string(k);
    seen.insert(n);
    names.push_back(n);
  }
  return names;
}

void writeText(const fs::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
  if (!out) throw Error("cannot write " + path.string());
}

const char* distributionName(MicrofacetDistribution d) { return d == MicrofacetDistribution::GGX ? "ggx" : "beckmann"; }

// ---------------------------------------------------------------------------------------------
// voxcone JSON

nlohmann::json materialJson(const Material& m) {
  nlohmann::json j;
  switch (m.type) {
    case MaterialType::Lambertian: j = {{"type", "lambertian"}, {"albedo", cleanVec(m.albedo)}}; break;
    case MaterialType::OrenNayar:
      j = {{"type", "oren_nayar"}, {"albedo", cleanVec(m.albedo)}, {"sigma_deg", clean(float(glm::degrees(m.sigmaRad)))}};
      break;
    case MaterialType::Mirror: j = {{"type", "mirror"}, {"specular", cleanVec(m.specular)}}; break;
    case MaterialType::Dielectric:
    case MaterialType::RoughDielectric:
      j = {{"type", m.type == MaterialType::Dielectric ? "dielectric" : "rough_dielectric"}, {"ior", clean(m.ior)},
           {"specular", cleanVec(m.specular)}};
      break;
    case MaterialType::Conductor:
    case MaterialType::RoughConductor:
      j = {{"type", m.type == MaterialType::Conductor ? "conductor" : "rough_conductor"}, {"eta", cleanVec(m.eta)},
           {"k", cleanVec(m.k)}, {"specular", cleanVec(m.specular)}};
      break;
    case MaterialType::Plastic:
    case MaterialType::RoughPlastic:
      j = {{"type", m.type == MaterialType::Plastic ? "plastic" : "rough_plastic"}, {"albedo", cleanVec(m.albedo)},
           {"ior", clean(m.ior)}, {"specular", cleanVec(m.specular)}};
      if (m.coatNonlinear) j["nonlinear"] = true;
      break;
    case MaterialType::ThinDielectric:
      j = {{"type", "thin_dielectric"}, {"ior", clean(m.ior)}, {"specular", cleanVec(m.specular)}};
      break;
  }
  if (m.type == MaterialType::RoughConductor || m.type == MaterialType::RoughDielectric ||
      m.type == MaterialType::RoughPlastic) {
    j["roughness"] = clean(m.roughness);
    j["distribution"] = distributionName(m.distribution);
  }
  if (m.isEmissive()) j["emission"] = cleanVec(m.emission);
  if (m.twoSidedEmission) j["two_sided_emission"] = true;
  if (!m.twoSided && !m.isTransmissive()) j["two_sided"] = false;
  return j;
}

// ---------------------------------------------------------------------------------------------
// Mitsuba XML

/// The <bsdf> of material `m` (without emission), indented by `pad`.
/// `texture`: the albedo's bitmap file as the scene names it, empty for none.
std::string bsdfXml(const Material& m, const std::string& id, const std::string& texture, const std::string& pad) {
  std::ostringstream os;
  const bool wrap = m.twoSided && !m.isTransmissive();
  const std::string idAttr = " id=\"" + xmlEscape(id) + "\"";
  std::string in = pad;
  if (wrap) {
    os << pad << "<bsdf type=\"twosided\"" << idAttr << ">\n";
    in += "  ";
  }
  const std::string ownId = wrap ? "" : idAttr;
  const auto rgb = [&](const char* name, const Vec3& v) {
    os << in << "  <rgb name=\"" << name << "\" value=\"" << vecText(v) << "\"/>\n";
  };
  const auto rough = [&] {
    os << in << "  <float name=\"alpha\" value=\"" << floatText(m.roughness) << "\"/>\n";
    os << in << "  <string name=\"distribution\" value=\"" << distributionName(m.distribution) << "\"/>\n";
  };
  // The diffuse albedo, a colour or a bitmap.
  const auto albedo = [&](const char* name) {
    if (texture.empty()) {
      rgb(name, m.albedo);
      return;
    }
    if (m.albedo != Vec3(1.0f))
      throw SceneError(m.name, "", "a textured albedo with a factor other than 1 has no Mitsuba 3 form");
    os << in << "  <texture type=\"bitmap\" name=\"" << name << "\">\n"
       << in << "    <string name=\"filename\" value=\"" << xmlEscape(texture) << "\"/>\n"
       << in << "  </texture>\n";
  };
  const auto iors = [&] {
    os << in << "  <float name=\"int_ior\" value=\"" << floatText(m.ior) << "\"/>\n";
    os << in << "  <float name=\"ext_ior\" value=\"1\"/>\n";
  };
  switch (m.type) {
    case MaterialType::Lambertian:
      os << in << "<bsdf type=\"diffuse\"" << ownId << ">\n";
      albedo("reflectance");
      break;
    case MaterialType::Plastic:
    case MaterialType::RoughPlastic:
      os << in << "<bsdf type=\"" << (m.type == MaterialType::Plastic ? "plastic" : "roughplastic") << "\"" << ownId << ">\n";
      albedo("diffuse_reflectance");
      rgb("specular_reflectance", m.specular);
      iors();
      if (m.coatNonlinear) os << in << "  <boolean name=\"nonlinear\" value=\"true\"/>\n";
      if (m.type == MaterialType::RoughPlastic) rough();
      break;
    case MaterialType::ThinDielectric:
      os << in << "<bsdf type=\"thindielectric\"" << ownId << ">\n";
      iors();
      rgb("specular_reflectance", m.specular);
      rgb("specular_transmittance", m.specular);
      break;
    case MaterialType::OrenNayar:
      throw SceneError(m.name, "", "material type oren_nayar has no Mitsuba 3 BSDF");
    case MaterialType::Mirror:
      // Mitsuba's conductor without eta, k or material is a perfect mirror.
      os << in << "<bsdf type=\"conductor\"" << ownId << ">\n";
      rgb("specular_reflectance", m.specular);
      break;
    case MaterialType::Conductor:
    case MaterialType::RoughConductor:
      os << in << "<bsdf type=\"" << (m.type == MaterialType::Conductor ? "conductor" : "roughconductor") << "\"" << ownId << ">\n";
      rgb("eta", m.eta);
      rgb("k", m.k);
      rgb("specular_reflectance", m.specular);
      if (m.type == MaterialType::RoughConductor) rough();
      break;
    case MaterialType::Dielectric:
    case MaterialType::RoughDielectric:
      os << in << "<bsdf type=\"" << (m.type == MaterialType::Dielectric ? "dielectric" : "roughdielectric") << "\"" << ownId << ">\n";
      iors();
      rgb("specular_reflectance", m.specular);
      rgb("specular_transmittance", m.specular);
      if (m.type == MaterialType::RoughDielectric) rough();
      break;
  }
  os << in << "</bsdf>\n";
  if (wrap) os << pad << "</bsdf>\n";
  return os.str();
}

/// An image file (an environment map's, a texture's) as the scene at `scenePath` names it:
/// relative to its folder.
std::string fileFromScene(const std::string& file, const fs::path& scenePath) {
  if (file.empty()) throw Error("an environment map or texture has no file to refer to");
  std::error_code ec;
  const fs::path rel = fs::relative(fs::absolute(file), fs::absolute(scenePath).parent_path(), ec);
  return ec || rel.empty() ? fs::absolute(file).string() : rel.string();
}

/// voxcone's environment frame in Mitsuba's envmap frame (mitsuba_loader.cpp): Mitsuba's
/// to_world is voxcone's times the inverse of this.
glm::mat3 mitsubaFromVoxcone() { return glm::mat3(Vec3(0, 0, 1), Vec3(0, 1, 0), Vec3(-1, 0, 0)); }

}  // namespace

void writeJsonScene(const Scene& scene, const std::string& jsonPath) {
  const fs::path path(jsonPath);
  const std::vector<std::string> names = materialNames(scene);
  nlohmann::json j;
  const Camera& c = scene.camera;
  j["camera"] = {{"position", cleanVec(c.position())}, {"target", cleanVec(c.target())}, {"up", cleanVec(c.up())},
                 {"fov_y_deg", clean(c.fovYDeg())}};
  const RenderSettings& s = scene.render;
  j["render"] = {{"width", s.width}, {"height", s.height}, {"spp", s.spp}, {"max_depth", s.maxDepth}, {"seed", s.seed},
                 {"method", s.method}, {"sampler", samplerNames()[size_t(s.sampler)]}};
  if (!s.lightTree) j["render"]["light_sampler"] = "power";
  if (s.lightSplitDeg != RenderSettings().lightSplitDeg) j["render"]["light_split"] = s.lightSplitDeg;
  if (s.photons) j["render"]["photons"] = s.photons;
  if (s.causticPhotons) j["render"]["caustic_photons"] = s.causticPhotons;
  // Only the materials some triangle uses (a Mitsuba BSDF no shape names has no triangles).
  std::set<uint32_t> used(scene.triMaterial.begin(), scene.triMaterial.end());
  j["materials"] = nlohmann::json::object();
  for (uint32_t m : used) {
    const Material& mat = scene.materials[m];
    j["materials"][names[m]] = materialJson(mat);
    if (mat.albedoTexture >= 0)
      j["materials"][names[m]]["albedo_texture"] = fileFromScene(scene.textures[size_t(mat.albedoTexture)]->file, path);
  }
  j["shapes"] = nlohmann::json::array();
  for (const MeshRun& r : writeMeshes(scene, path)) {
    nlohmann::json sh = {{"type", "mesh"}, {"name", r.name}, {"file", r.relPath}, {"material", names[r.material]}};
    if (r.smooth) sh["smooth_normals"] = true;
    j["shapes"].push_back(sh);
  }
  j["lights"] = nlohmann::json::array();
  for (const PointLight& pl : scene.pointLights)
    j["lights"].push_back({{"type", "point"}, {"position", cleanVec(pl.position)}, {"intensity", cleanVec(pl.intensity)}});
  for (const DirectionalLight& dl : scene.directionalLights) {
    nlohmann::json l = {{"type", "directional"}, {"direction", cleanVec(dl.direction)}, {"irradiance", cleanVec(dl.irradiance)}};
    if (!dl.isDelta()) l["angle_deg"] = clean(float(glm::degrees(2.0 * double(dl.halfAngle))));
    j["lights"].push_back(l);
  }
  if (const auto& env = scene.environment) {
    nlohmann::json e = {{"type", "environment"}};
    if (env->isConstant()) {
      e["radiance"] = cleanVec(env->constantRadiance());
    } else {
      e["file"] = fileFromScene(env->file, path);
      e["scale"] = clean(env->scale());
      const glm::mat3& m = env->toWorld();
      // A turn about +y as rotate_deg (its first column is (cos, 0, -sin)), else the matrix.
      if (std::fabs(m[1].y - 1.0f) < 1e-6f && std::fabs(m[0].y) < 1e-6f && std::fabs(m[2].y) < 1e-6f) {
        e["rotate_deg"] = clean(glm::degrees(std::atan2(-m[0].z, m[0].x)));
      } else {
        e["to_world"] = nlohmann::json::array();
        for (int row = 0; row < 3; ++row) e["to_world"].push_back(cleanVec(Vec3(m[0][row], m[1][row], m[2][row])));
      }
    }
    j["lights"].push_back(e);
  }
  writeText(path, j.dump(2) + "\n");
}

void writeMitsubaScene(const Scene& scene, const std::string& xmlPath) {
  const fs::path path(xmlPath);
  const std::vector<std::string> names = materialNames(scene);
  const std::string from = scene.sourcePath.empty() ? "a voxcone scene" : scene.sourcePath;
  std::set<uint32_t> used(scene.triMaterial.begin(), scene.triMaterial.end());
  // What Mitsuba cannot say, before anything is written.
  for (uint32_t m : used) {
    const Material& mat = scene.materials[m];
    if (mat.type == MaterialType::OrenNayar)
      throw SceneError(from, "materials." + names[m], "oren_nayar has no Mitsuba 3 BSDF");
    if (mat.twoSidedEmission)
      throw SceneError(from, "materials." + names[m], "two_sided_emission: Mitsuba's area emitter emits on one side");
  }
  const RenderSettings& s = scene.render;
  if (s.seed > uint64_t(INT32_MAX)) throw SceneError(from, "render.seed", "Mitsuba's sampler seed is a 32-bit integer");
  for (const DirectionalLight& dl : scene.directionalLights)
    if (!dl.isDelta()) throw SceneError(from, "lights", "a sun of finite angle_deg has no Mitsuba 3 form (its directional is a delta light)");

  std::ostringstream os;
  os << "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n";
  os << "<!-- Written by voxcone convert from " << xmlEscape(from) << ". -->\n";
  os << "<scene version=\"3.0.0\">\n";
  if (s.method != "path")
    os << "  <!-- '" << xmlEscape(s.method) << "' is voxcone's own integrator; Mitsuba renders type=\"path\". -->\n";
  os << "  <integrator type=\"" << xmlEscape(s.method) << "\">\n";
  os << "    <integer name=\"max_depth\" value=\"" << s.maxDepth << "\"/>\n";
  if (s.method == "voxcone" || s.method == "pm") {
    if (s.photons) os << "    <integer name=\"photons\" value=\"" << s.photons << "\"/>\n";
    if (s.causticPhotons) os << "    <integer name=\"caustic_photons\" value=\"" << s.causticPhotons << "\"/>\n";
  } else if (s.photons || s.causticPhotons) {
    throw SceneError(from, "render.photons", "photons are a voxcone/pm setting; method is " + s.method);
  }
  os << "  </integrator>\n";
  const Camera& c = scene.camera;
  os << "  <sensor type=\"perspective\">\n";
  os << "    <float name=\"fov\" value=\"" << floatText(c.fovYDeg()) << "\"/>\n";
  os << "    <string name=\"fov_axis\" value=\"y\"/>\n";
  os << "    <transform name=\"to_world\">\n";
  os << "      <lookat origin=\"" << vecText(c.position()) << "\" target=\"" << vecText(c.target()) << "\" up=\""
     << vecText(c.up()) << "\"/>\n";
  os << "    </transform>\n";
  os << "    <sampler type=\"" << (s.sampler == SamplerKind::Independent ? "independent" : "ldsampler") << "\">\n";
  os << "      <integer name=\"sample_count\" value=\"" << s.spp << "\"/>\n";
  os << "      <integer name=\"seed\" value=\"" << s.seed << "\"/>\n";
  os << "    </sampler>\n";
  os << "    <film type=\"hdrfilm\">\n";
  os << "      <integer name=\"width\" value=\"" << s.width << "\"/>\n";
  os << "      <integer name=\"height\" value=\"" << s.height << "\"/>\n";
  os << "      <rfilter type=\"box\"/>\n";
  os << "    </film>\n";
  os << "  </sensor>\n";
  for (uint32_t m : used) {
    const Material& mat = scene.materials[m];
    const std::string texture =
        mat.albedoTexture >= 0 ? fileFromScene(scene.textures[size_t(mat.albedoTexture)]->file, path) : std::string();
    os << bsdfXml(mat, names[m], texture, "  ");
  }
  const std::set<std::string> materialIds(names.begin(), names.end());
  std::set<std::string> shapeIds;
  for (const MeshRun& r : writeMeshes(scene, path)) {
    // Ids share one namespace in Mitsuba: a shape named like a material is renamed.
    std::string id = r.name;
    for (int k = 2; materialIds.count(id) || shapeIds.count(id); ++k) id = r.name + "-shape" + (k > 2 ? std::to_string(k) : "");
    shapeIds.insert(id);
    const Material& mat = scene.materials[r.material];
    os << "  <shape type=\"ply\" id=\"" << xmlEscape(id) << "\">\n";
    os << "    <string name=\"filename\" value=\"" << xmlEscape(r.relPath) << "\"/>\n";
    os << "    <boolean name=\"face_normals\" value=\"" << (r.smooth ? "false" : "true") << "\"/>\n";
    os << "    <ref id=\"" << xmlEscape(names[r.material]) << "\"/>\n";
    if (mat.isEmissive())
      os << "    <emitter type=\"area\">\n      <rgb name=\"radiance\" value=\"" << vecText(mat.emission)
         << "\"/>\n    </emitter>\n";
    os << "  </shape>\n";
  }
  for (const PointLight& pl : scene.pointLights) {
    os << "  <emitter type=\"point\">\n";
    os << "    <point name=\"position\" value=\"" << vecText(pl.position) << "\"/>\n";
    os << "    <rgb name=\"intensity\" value=\"" << vecText(pl.intensity) << "\"/>\n";
    os << "  </emitter>\n";
  }
  for (const DirectionalLight& dl : scene.directionalLights) {
    os << "  <emitter type=\"directional\">\n";
    os << "    <vector name=\"direction\" value=\"" << vecText(dl.direction) << "\"/>\n";
    os << "    <rgb name=\"irradiance\" value=\"" << vecText(dl.irradiance) << "\"/>\n";
    os << "  </emitter>\n";
  }
  if (const auto& env = scene.environment) {
    if (env->isConstant()) {
      os << "  <emitter type=\"constant\">\n";
      os << "    <rgb name=\"radiance\" value=\"" << vecText(env->constantRadiance()) << "\"/>\n";
    } else {
      os << "  <emitter type=\"envmap\">\n";
      os << "    <string name=\"filename\" value=\"" << xmlEscape(fileFromScene(env->file, path)) << "\"/>\n";
      os << "    <float name=\"scale\" value=\"" << floatText(env->scale()) << "\"/>\n";
      const glm::mat3 m = env->toWorld() * glm::transpose(mitsubaFromVoxcone());
      os << "    <transform name=\"to_world\">\n      <matrix value=\"";
      for (int row = 0; row < 4; ++row)
        for (int col = 0; col < 4; ++col)
          os << (row || col ? " " : "") << (row < 3 && col < 3 ? floatText(m[col][row]) : row == col ? "1" : "0");
      os << "\"/>\n    </transform>\n";
    }
    os << "  </emitter>\n";
  }
  os << "</scene>\n";
  writeText(path, os.str());
}

}  // namespace voxcone

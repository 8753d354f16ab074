/// \file gltf_loader.cpp
/// glTF 2.0 through tinygltf (header-only; its implementation and stb_image's compiled here).

#include "voxcone/scene/gltf.h"

#include "scene_build.h"
#include "voxcone/core/error.h"
#include "voxcone/image/image_io.h"

#define TINYGLTF_IMPLEMENTATION
#define TINYGLTF_NO_STB_IMAGE_WRITE
#define TINYGLTF_NO_INCLUDE_STB_IMAGE
#define STB_IMAGE_IMPLEMENTATION
#define STBI_NO_STDIO_WARNINGS
#include <stb/stb_image.h>
#include <tiny_gltf.h>

#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <map>
#include <set>

namespace voxcone {

namespace {

constexpr double kWattsPerLumen = 1.0 / 683.0;

std::string firstLine(const std::string& s) {
  std::string line = s.substr(0, s.find('\n'));
  while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
  return line;
}

std::string lowerExtension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return ext;
}

/// Reads one glTF file into a Scene's meshes, materials, camera and lights.
class GltfReader {
public:
  GltfReader(Scene& scene, std::string path, std::vector<std::string>& warnings)
      : m_scene(scene), m_path(std::move(path)), m_warnings(warnings) {}

  void load() {
    tinygltf::TinyGLTF loader;
    std::string err, warn;
    std::error_code ec;
    if (!std::filesystem::is_regular_file(m_path, ec)) fail("cannot open file");
    const bool ok = lowerExtension(m_path) == ".glb" ? loader.LoadBinaryFromFile(&m_model, &err, &warn, m_path)
                                                     : loader.LoadASCIIFromFile(&m_model, &err, &warn, m_path);
    if (!ok || !err.empty()) fail(err.empty() ? "cannot parse glTF" : firstLine(err));
    static const std::set<std::string> understood = {"KHR_lights_punctual", "KHR_materials_emissive_strength",
                                                     "KHR_materials_transmission", "KHR_materials_ior"};
    for (const std::string& e : m_model.extensionsRequired)
      if (!understood.count(e)) fail("requires extension " + e + ", which voxcone does not read");
  }

  /// Walk the default scene (or the first), appending meshes; with `all`, also the first
  /// perspective camera and the lights.
  void walk(const glm::dmat4& root, bool all) {
    m_all = all;
    if (m_model.scenes.empty()) {
      // No scene: every root node (nodes no other node lists as a child).
      std::vector<bool> child(m_model.nodes.size(), false);
      for (const tinygltf::Node& n : m_model.nodes)
        for (int c : n.children)
          if (c >= 0 && size_t(c) < child.size()) child[size_t(c)] = true;
      for (size_t i = 0; i < m_model.nodes.size(); ++i)
        if (!child[i]) visit(int(i), root, 0);
      return;
    }
    const int s = m_model.defaultScene >= 0 ? m_model.defaultScene : 0;
    if (size_t(s) >= m_model.scenes.size()) fail("scene index out of range");
    for (int n : m_model.scenes[size_t(s)].nodes) visit(n, root, 0);
  }

  bool hasCamera() const { return m_haveCamera; }
  double aspect() const { return m_aspect; }

private:
  [[noreturn]] void fail(const std::string& what) const { throw SceneError(m_path, "", what); }
  void warn(const std::string& what) {
    const std::string line = m_path + ": " + what;
    if (std::find(m_warnings.begin(), m_warnings.end(), line) == m_warnings.end()) m_warnings.push_back(line);
  }

  static glm::dmat4 localMatrix(const tinygltf::Node& n) {
    if (n.matrix.size() == 16) {
      glm::dmat4 m;
      for (int c = 0; c < 4; ++c)
        for (int r = 0; r < 4; ++r) m[c][r] = n.matrix[size_t(c * 4 + r)];  // column-major
      return m;
    }
    glm::dmat4 t(1.0), r(1.0), s(1.0);
    if (n.translation.size() == 3) t = glm::translate(glm::dmat4(1.0), glm::dvec3(n.translation[0], n.translation[1], n.translation[2]));
    if (n.rotation.size() == 4) {
      const glm::dquat q(n.rotation[3], n.rotation[0], n.rotation[1], n.rotation[2]);  // (w, x, y, z)
      r = glm::mat4_cast(glm::normalize(q));
    }
    if (n.scale.size() == 3) s = glm::scale(glm::dmat4(1.0), glm::dvec3(n.scale[0], n.scale[1], n.scale[2]));
    return t * r * s;
  }

  void visit(int index, const glm::dmat4& parent, int depth) {
    if (index < 0 || size_t(index) >= m_model.nodes.size()) fail("node index out of range");
    if (depth > 256) fail("node hierarchy deeper than 256 (a cycle?)");
    const tinygltf::Node& n = m_model.nodes[size_t(index)];
    const glm::dmat4 world = parent * localMatrix(n);
    if (n.mesh >= 0) addMesh(n, world);
    if (n.skin >= 0) warn("node '" + n.name + "': its skin is dropped (rendered in its rest pose)");
    if (m_all && n.camera >= 0 && !m_haveCamera) addCamera(n, world);
    if (m_all) {
      const auto it = n.extensions.find("KHR_lights_punctual");
      if (it != n.extensions.end() && it->second.Has("light")) addLight(it->second.Get("light").GetNumberAsInt(), world);
    }
    for (int c : n.children) visit(c, world, depth + 1);
  }

  // ---- accessors

  /// Element `i` of accessor `a` as up to 4 doubles (normalized integers mapped to [0, 1] or
  /// [-1, 1]).
  struct View {
    const unsigned char* data = nullptr;
    size_t stride = 0, count = 0;
    int components = 0, type = 0;
    bool normalized = false;
  };

  View view(int accessorIndex, const char* what) const {
    if (accessorIndex < 0 || size_t(accessorIndex) >= m_model.accessors.size())
      fail(std::string(what) + ": accessor index out of range");
    const tinygltf::Accessor& a = m_model.accessors[size_t(accessorIndex)];
    if (a.sparse.isSparse) fail(std::string(what) + ": sparse accessors are not supported");
    if (a.bufferView < 0 || size_t(a.bufferView) >= m_model.bufferViews.size())
      fail(std::string(what) + ": accessor without a buffer view");
    const tinygltf::BufferView& bv = m_model.bufferViews[size_t(a.bufferView)];
    if (bv.buffer < 0 || size_t(bv.buffer) >= m_model.buffers.size()) fail(std::string(what) + ": buffer index out of range");
    const tinygltf::Buffer& b = m_model.buffers[size_t(bv.buffer)];
    View v;
    v.components = tinygltf::GetNumComponentsInType(uint32_t(a.type));
    v.type = a.componentType;
    v.normalized = a.normalized;
    const int size = tinygltf::GetComponentSizeInBytes(uint32_t(a.componentType));
    if (v.components <= 0 || size <= 0) fail(std::string(what) + ": unknown accessor type");
    const size_t elem = size_t(v.components) * size_t(size);
    v.stride = bv.byteStride > 0 ? bv.byteStride : elem;
    v.count = a.count;
    const size_t begin = bv.byteOffset + a.byteOffset;
    const size_t end = a.count == 0 ? begin : begin + (a.count - 1) * v.stride + elem;
    if (end > b.data.size() || end > bv.byteOffset + bv.byteLength || v.stride < elem)
      fail(std::string(what) + ": accessor reaches past its buffer");
    v.data = b.data.data() + begin;
    return v;
  }

  static double component(const View& v, size_t i, int c) {
    const unsigned char* p = v.data + i * v.stride;
    switch (v.type) {
      case TINYGLTF_COMPONENT_TYPE_FLOAT: {
        float f;
        std::memcpy(&f, p + 4 * c, 4);
        return f;
      }
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return v.normalized ? p[c] / 255.0 : p[c];
      case TINYGLTF_COMPONENT_TYPE_BYTE: {
        const int8_t x = int8_t(p[c]);
        return v.normalized ? std::max(x / 127.0, -1.0) : x;
      }
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
        uint16_t x;
        std::memcpy(&x, p + 2 * c, 2);
        return v.normalized ? x / 65535.0 : x;
      }
      case TINYGLTF_COMPONENT_TYPE_SHORT: {
        int16_t x;
        std::memcpy(&x, p + 2 * c, 2);
        return v.normalized ? std::max(x / 32767.0, -1.0) : x;
      }
      case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
        uint32_t x;
        std::memcpy(&x, p + 4 * c, 4);
        return x;
      }
      default: return 0.0;
    }
  }

  // ---- meshes

  void addMesh(const tinygltf::Node& node, const glm::dmat4& world) {
    if (size_t(node.mesh) >= m_model.meshes.size()) fail("mesh index out of range");
    const tinygltf::Mesh& mesh = m_model.meshes[size_t(node.mesh)];
    const glm::dmat3 lin(world);
    const glm::dmat3 nxf = glm::transpose(glm::inverse(lin));
    const bool mirror = glm::determinant(lin) < 0.0;
    for (size_t pi = 0; pi < mesh.primitives.size(); ++pi) {
      const tinygltf::Primitive& prim = mesh.primitives[pi];
      const std::string where = "mesh '" + mesh.name + "' primitive " + std::to_string(pi);
      if (prim.mode != TINYGLTF_MODE_TRIANGLES && prim.mode != -1) {
        if (prim.mode == TINYGLTF_MODE_TRIANGLE_STRIP || prim.mode == TINYGLTF_MODE_TRIANGLE_FAN)
          fail(where + ": triangle strips and fans are not supported (triangles only)");
        warn(where + ": points or lines are dropped (no surface)");
        continue;
      }
      if (!prim.targets.empty()) warn(where + ": morph targets are dropped");
      const auto attr = [&](const char* name) {
        const auto it = prim.attributes.find(name);
        return it == prim.attributes.end() ? -1 : it->second;
      };
      if (attr("POSITION") < 0) fail(where + ": no POSITION");
      const View pv = view(attr("POSITION"), (where + " POSITION").c_str());
      if (pv.components != 3) fail(where + ": POSITION must be VEC3");
      std::vector<Vec3> pos(pv.count), nrm;
      for (size_t i = 0; i < pv.count; ++i) {
        const glm::dvec4 p(component(pv, i, 0), component(pv, i, 1), component(pv, i, 2), 1.0);
        pos[i] = Vec3(glm::dvec3(world * p));
        if (!isFinite(pos[i])) fail(where + ": non-finite position");
      }
      if (attr("NORMAL") >= 0) {
        const View nv = view(attr("NORMAL"), (where + " NORMAL").c_str());
        if (nv.components != 3 || nv.count != pv.count) fail(where + ": NORMAL must be VEC3, one per position");
        nrm.resize(nv.count);
        for (size_t i = 0; i < nv.count; ++i) {
          const glm::dvec3 n = nxf * glm::dvec3(component(nv, i, 0), component(nv, i, 1), component(nv, i, 2));
          const double len = glm::length(n);
          nrm[i] = len > 0.0 && std::isfinite(len) ? Vec3(n / len) : Vec3(0.0f, 0.0f, 1.0f);
        }
      }
      std::vector<Vec2> uvs;
      if (attr("TEXCOORD_0") >= 0) {
        const View tv = view(attr("TEXCOORD_0"), (where + " TEXCOORD_0").c_str());
        if (tv.components != 2 || tv.count != pv.count) fail(where + ": TEXCOORD_0 must be VEC2, one per position");
        uvs.resize(tv.count);
        for (size_t i = 0; i < tv.count; ++i) uvs[i] = Vec2(float(component(tv, i, 0)), float(1.0 - component(tv, i, 1)));
      }
      std::vector<UVec3> tris;
      if (prim.indices >= 0) {
        const View iv = view(prim.indices, (where + " indices").c_str());
        if (iv.components != 1 || iv.count % 3 != 0) fail(where + ": indices must be SCALAR, a multiple of 3");
        for (size_t i = 0; i + 2 < iv.count; i += 3) {
          UVec3 t;
          for (int k = 0; k < 3; ++k) {
            const double x = component(iv, i + size_t(k), 0);
            if (!(x >= 0.0 && x < double(pv.count))) fail(where + ": index out of range");
            t[k] = uint32_t(x);
          }
          tris.push_back(t);
        }
      } else {
        if (pv.count % 3 != 0) fail(where + ": non-indexed triangles need a multiple of 3 positions");
        for (uint32_t i = 0; i + 2 < pv.count; i += 3) tris.push_back({i, i + 1, i + 2});
      }
      if (mirror)
        for (UVec3& t : tris) std::swap(t.y, t.z);
      const uint32_t mat = material(prim.material, !uvs.empty(), where);
      detail::appendShape(m_scene, mesh.name.empty() ? "gltf-mesh" + std::to_string(node.mesh) : mesh.name, pos, nrm,
                          uvs, tris, {mat}, !nrm.empty());
    }
  }

  // ---- materials

  static double numberIn(const tinygltf::ExtensionMap& ext, const char* extension, const char* key, double def) {
    const auto it = ext.find(extension);
    if (it == ext.end() || !it->second.Has(key)) return def;
    return it->second.Get(key).GetNumberAsDouble();
  }

  /// Texture `index` (the base colour: sRGB-encoded 8 or 16 bits, decoded to linear).
  int32_t texture(int index, const std::string& what) {
    const auto cached = m_textures.find(index);
    if (cached != m_textures.end()) return cached->second;
    if (index < 0 || size_t(index) >= m_model.textures.size()) fail(what + ": texture index out of range");
    const int source = m_model.textures[size_t(index)].source;
    if (source < 0 || size_t(source) >= m_model.images.size()) fail(what + ": texture without an image");
    const tinygltf::Image& img = m_model.images[size_t(source)];
    if (img.width < 1 || img.height < 1 || img.component < 3 || (img.bits != 8 && img.bits != 16) ||
        img.image.size() < size_t(img.width) * size_t(img.height) * size_t(img.component) * size_t(img.bits / 8))
      fail(what + ": image '" + (img.uri.empty() ? img.name : img.uri) + "' could not be decoded as 8- or 16-bit RGB(A)");
    std::vector<Vec3> texels(size_t(img.width) * size_t(img.height));
    for (size_t p = 0; p < texels.size(); ++p)
      for (int c = 0; c < 3; ++c) {
        const size_t at = p * size_t(img.component) + size_t(c);
        float code;
        if (img.bits == 8) {
          code = img.image[at] / 255.0f;
        } else {
          uint16_t x;
          std::memcpy(&x, img.image.data() + 2 * at, 2);
          code = x / 65535.0f;
        }
        texels[p][c] = srgbToLinear(code);
      }
    auto t = std::make_shared<Texture>(img.width, img.height, std::move(texels));
    t->file = m_path + "#image" + std::to_string(source);
    m_scene.textures.push_back(t);
    const int32_t id = int32_t(m_scene.textures.size() - 1);
    m_textures[index] = id;
    return id;
  }

  uint32_t material(int index, bool hasUvs, const std::string& where) {
    const auto cached = m_materials.find(index);
    if (cached != m_materials.end() && (m_scene.materials[cached->second].albedoTexture < 0 || hasUvs)) return cached->second;
    Material m;
    m.twoSided = true;
    if (index < 0) {
      // glTF's default material: white, metallic 1, roughness 1.
      m.name = m_path + ":default";
      m.type = MaterialType::RoughConductor;
      m.eta = Vec3(0.0f);
      m.k = Vec3(1.0f);
      m.specular = Vec3(1.0f);
      m.roughness = 1.0f;
    } else {
      if (size_t(index) >= m_model.materials.size()) fail(where + ": material index out of range");
      const tinygltf::Material& gm = m_model.materials[size_t(index)];
      const std::string name = gm.name.empty() ? "material" + std::to_string(index) : gm.name;
      const std::string mw = "material '" + name + "'";
      m.name = m_path + ":" + name;
      const tinygltf::PbrMetallicRoughness& pbr = gm.pbrMetallicRoughness;
      Vec3 base(1.0f);
      if (pbr.baseColorFactor.size() >= 3)
        base = Vec3(float(pbr.baseColorFactor[0]), float(pbr.baseColorFactor[1]), float(pbr.baseColorFactor[2]));
      base = glm::clamp(base, Vec3(0.0f), Vec3(1.0f));
      int32_t tex = -1;
      if (pbr.baseColorTexture.index >= 0) {
        if (pbr.baseColorTexture.texCoord != 0) fail(mw + ": base colour texture on TEXCOORD_" + std::to_string(pbr.baseColorTexture.texCoord) + " (voxcone reads TEXCOORD_0)");
        if (pbr.baseColorTexture.extensions.count("KHR_texture_transform")) warn(mw + ": KHR_texture_transform is dropped");
        tex = texture(pbr.baseColorTexture.index, mw);
        if (!hasUvs) fail(where + ": " + mw + " has a base colour texture but the primitive has no TEXCOORD_0");
      }
      if (pbr.metallicRoughnessTexture.index >= 0) warn(mw + ": its metallic-roughness texture is dropped (the factors are used)");
      if (gm.normalTexture.index >= 0) warn(mw + ": its normal map is dropped");
      if (gm.occlusionTexture.index >= 0) warn(mw + ": its occlusion texture is dropped");
      if (gm.alphaMode != "OPAQUE") warn(mw + ": alphaMode " + gm.alphaMode + " is rendered opaque");
      const double metallic = std::clamp(pbr.metallicFactor, 0.0, 1.0);
      const double roughness = std::clamp(pbr.roughnessFactor, 0.0, 1.0);
      const double transmission = numberIn(gm.extensions, "KHR_materials_transmission", "transmissionFactor", 0.0);
      const float alpha = float(roughness * roughness);
      // A texture's mean where the model takes one colour (a metal's or glass's tint).
      const Vec3 tint = tex >= 0 ? glm::clamp(base * m_scene.textures[size_t(tex)]->mean(), Vec3(0.0f), Vec3(1.0f)) : base;
      if (transmission > 0.0 && metallic < 1.0) {
        if (transmission < 1.0) warn(mw + ": transmission " + std::to_string(transmission) + " rendered as 1 (a dielectric)");
        m.type = alpha >= 1e-4f ? MaterialType::RoughDielectric : MaterialType::Dielectric;
        m.ior = float(std::max(1.0001, numberIn(gm.extensions, "KHR_materials_ior", "ior", 1.5)));
        m.specular = tint;
        m.roughness = std::max(alpha, 1e-4f);
        if (tex >= 0) warn(mw + ": its base colour texture tints the glass by its mean");
      } else if (metallic >= 0.5) {
        if (metallic < 1.0) warn(mw + ": metallic " + std::to_string(metallic) + " rendered as a metal (no blend of metal and diffuse)");
        m.type = alpha >= 1e-4f ? MaterialType::RoughConductor : MaterialType::Conductor;
        m.eta = Vec3(0.0f);  // with k 1: Fresnel 1 at every angle, the tint the base colour
        m.k = Vec3(1.0f);
        m.specular = tint;
        m.roughness = std::max(alpha, 1e-4f);
        m.distribution = MicrofacetDistribution::GGX;
        if (tex >= 0) warn(mw + ": its base colour texture tints the metal by its mean");
      } else {
        if (metallic > 0.0) warn(mw + ": metallic " + std::to_string(metallic) + " rendered as 0 (a dielectric)");
        // glTF's dielectric BRDF is a Fresnel-weighted specular layer over the diffuse base:
        // voxcone's coated diffuse of the same index (GGX, alpha = roughness^2). At roughness 1
        // that layer is a faint haze over the whole hemisphere: a Lambertian, as Blender's
        // Diffuse BSDF takes it.
        m.albedo = base;
        m.albedoTexture = tex;
        if (roughness < 1.0) {
          m.type = alpha >= 1e-4f ? MaterialType::RoughPlastic : MaterialType::Plastic;
          m.ior = float(std::max(1.0001, numberIn(gm.extensions, "KHR_materials_ior", "ior", 1.5)));
          m.roughness = std::max(alpha, 1e-4f);
          m.distribution = MicrofacetDistribution::GGX;
        } else {
          m.type = MaterialType::Lambertian;
        }
      }
      Vec3 emissive(0.0f);
      if (gm.emissiveFactor.size() >= 3)
        emissive = Vec3(float(gm.emissiveFactor[0]), float(gm.emissiveFactor[1]), float(gm.emissiveFactor[2]));
      emissive *= float(numberIn(gm.extensions, "KHR_materials_emissive_strength", "emissiveStrength", 1.0));
      if (gm.emissiveTexture.index >= 0) warn(mw + ": its emissive texture is dropped (emissiveFactor is used)");
      if (!isFinite(emissive) || emissive.x < 0.0f || emissive.y < 0.0f || emissive.z < 0.0f) fail(mw + ": emission must be finite and >= 0");
      m.emission = emissive;
      m.twoSidedEmission = !isBlack(emissive);
    }
    m_scene.materials.push_back(m);
    const uint32_t id = uint32_t(m_scene.materials.size() - 1);
    m_materials[index] = id;
    return id;
  }

  // ---- camera and lights

  void addCamera(const tinygltf::Node& n, const glm::dmat4& world) {
    if (size_t(n.camera) >= m_model.cameras.size()) fail("camera index out of range");
    const tinygltf::Camera& c = m_model.cameras[size_t(n.camera)];
    if (c.type != "perspective") {
      warn("camera '" + c.name + "' (" + c.type + ") is skipped: voxcone renders perspective cameras");
      return;
    }
    const glm::dvec3 eye(world * glm::dvec4(0, 0, 0, 1));
    const glm::dvec3 forward = glm::normalize(glm::dmat3(world) * glm::dvec3(0, 0, -1));
    const glm::dvec3 up = glm::normalize(glm::dmat3(world) * glm::dvec3(0, 1, 0));
    const double fovDeg = c.perspective.yfov * 180.0 / 3.14159265358979323846;
    if (!(fovDeg > 0.0 && fovDeg < 180.0)) fail("camera '" + c.name + "': yfov must lie in (0, pi)");
    m_scene.camera = Camera(Vec3(eye), Vec3(eye + forward), Vec3(up), float(fovDeg));
    m_aspect = c.perspective.aspectRatio;
    m_haveCamera = true;
  }

  void addLight(int index, const glm::dmat4& world) {
    if (index < 0 || size_t(index) >= m_model.lights.size()) fail("light index out of range");
    const tinygltf::Light& l = m_model.lights[size_t(index)];
    Vec3 colour(1.0f);
    if (l.color.size() >= 3) colour = Vec3(float(l.color[0]), float(l.color[1]), float(l.color[2]));
    const float power = float(l.intensity * kWattsPerLumen);
    if (!(power >= 0.0f) || !std::isfinite(power)) fail("light '" + l.name + "': intensity must be finite and >= 0");
    if (l.range > 0.0) warn("light '" + l.name + "': its range is ignored (inverse-square falloff)");
    if (l.type == "point") {
      PointLight p;
      p.position = Vec3(glm::dvec3(world * glm::dvec4(0, 0, 0, 1)));
      p.intensity = colour * power;  // I(cd) / 683 W/sr
      m_scene.pointLights.push_back(p);
    } else if (l.type == "directional") {
      DirectionalLight d;
      d.direction = Vec3(glm::normalize(glm::dmat3(world) * glm::dvec3(0, 0, -1)));
      d.irradiance = colour * power;  // E(lx) / 683 W/m^2
      m_scene.directionalLights.push_back(d);
    } else {
      fail("light '" + l.name + "': " + l.type + " lights are not supported (point, directional)");
    }
  }

  Scene& m_scene;
  std::string m_path;
  std::vector<std::string>& m_warnings;
  tinygltf::Model m_model;
  bool m_all = false, m_haveCamera = false;
  double m_aspect = 0.0;
  std::map<int, uint32_t> m_materials;
  std::map<int, int32_t> m_textures;
};

}  // namespace

bool isGltfScenePath(const std::string& path) {
  const std::string ext = lowerExtension(path);
  return ext == ".gltf" || ext == ".glb";
}

Scene loadGltfScene(const std::string& path, std::vector<std::string>* warnings) {
  Scene scene;
  scene.sourcePath = path;
  scene.inputFiles.push_back(path);
  std::vector<std::string> local;
  GltfReader reader(scene, path, warnings ? *warnings : local);
  reader.load();
  reader.walk(glm::dmat4(1.0), true);
  if (!reader.hasCamera()) throw SceneError(path, "", "no perspective camera (voxcone renders a glTF scene from its first)");
  if (reader.aspect() > 0.0)
    scene.render.width = std::max(1, int(std::lround(double(scene.render.height) * reader.aspect())));
  if (!warnings)
    for (const std::string& w : local) std::cerr << "warning: " << w << "\n";
  detail::finishScene(scene, path);
  return scene;
}

void appendGltfMeshes(Scene& scene, const std::string& path, const glm::mat4& xf, std::vector<std::string>& warnings) {
  GltfReader reader(scene, path, warnings);
  reader.load();
  reader.walk(glm::dmat4(xf), false);
}

}  // namespace voxcone

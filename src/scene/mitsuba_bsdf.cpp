/// \file mitsuba_bsdf.cpp
/// Mitsuba 3 BSDFs and bitmap textures as voxcone materials (src/render/bsdf plugins).

#include "mitsuba_loader_impl.h"

namespace voxcone {
namespace mitsuba_xml {

namespace {

/// Mitsuba's named indices of refraction (Mitsuba 3 include/mitsuba/render/ior.h, after Hecht,
/// Optics, 4th ed., at about 589 nm).
const std::map<std::string, float>& iorTable() {
  static const std::map<std::string, float> table = {
      {"vacuum", 1.0f},          {"helium", 1.000036f},     {"hydrogen", 1.000132f},
      {"air", 1.000277f},        {"carbon dioxide", 1.00045f}, {"water", 1.3330f},
      {"acetone", 1.36f},        {"ethanol", 1.361f},       {"carbon tetrachloride", 1.461f},
      {"glycerol", 1.4729f},     {"benzene", 1.501f},       {"silicone oil", 1.52045f},
      {"bromine", 1.661f},       {"water ice", 1.31f},      {"fused quartz", 1.458f},
      {"pyrex", 1.470f},         {"acrylic glass", 1.49f},  {"polypropylene", 1.49f},
      {"bk7", 1.5046f},          {"sodium chloride", 1.544f}, {"amber", 1.55f},
      {"pet", 1.5750f},          {"diamond", 2.419f}};
  return table;
}

/// Conductor presets as linear RGB (eta, k). Mitsuba 3 integrates measured spectra at render
/// time; these are the same spectra (Mitsuba's data/ior) integrated to RGB as published in
/// Tungsten's ComplexIorData.hpp (B. Bitterli), rounded to 5 digits.
struct ConductorPreset {
  Vec3 eta, k;
};
const std::map<std::string, ConductorPreset>& conductorTable() {
  static const std::map<std::string, ConductorPreset> table = {
      {"Ag", {{0.15526f, 0.11672f, 0.13838f}, {4.8283f, 3.1222f, 2.1470f}}},
      {"Al", {{1.6575f, 0.88037f, 0.52123f}, {9.2239f, 6.2695f, 4.8370f}}},
      {"Au", {{0.14312f, 0.37496f, 1.4425f}, {3.9832f, 2.3857f, 1.6032f}}},
      {"Cr", {{4.3697f, 2.9167f, 1.6547f}, {5.2064f, 4.2314f, 3.7549f}}},
      {"Cu", {{0.20044f, 0.92403f, 1.1022f}, {3.9129f, 2.4528f, 2.1422f}}},
      {"W", {{4.3707f, 3.3003f, 2.9983f}, {3.5007f, 2.6049f, 2.2732f}}}};
  return table;
}

}  // namespace

int32_t MitsubaLoader::bitmapTexture(const Node& n) {
  allowAttrs(n, {"type", "id", "name"});
  Props p(*this, n);
  if (p.type() != "bitmap") fail(n, "unsupported texture plugin '" + p.type() + "' (voxcone maps bitmap)");
  fs::path file = p.getString("filename", "", true);
  if (file.is_relative()) file = fs::path(n.file->dir) / file;
  if (p.getBool("raw", false)) fail(n, "raw bitmaps are not supported (voxcone decodes 8-bit files from sRGB)");
  if (p.getString("filter_type", "bilinear") != "bilinear") fail(n, "filter_type: voxcone filters bilinearly");
  if (p.getString("wrap_mode", "repeat") != "repeat") fail(n, "wrap_mode: voxcone repeats");
  if (p.getTransform("to_uv") != glm::dmat4(1.0)) fail(n, "to_uv is not supported");
  p.finish();
  m_scene.inputFiles.push_back(file.string());
  try {
    return detail::textureIndex(m_scene, file.string());
  } catch (const Error& e) {
    fail(n, e.what());
  }
}

const Material& MitsubaLoader::bsdfMaterial(const Node& n) {
  const auto it = m_bsdfs.find(n.xml.internal_object());
  if (it != m_bsdfs.end()) return it->second;
  Material m = parseBsdf(n, false);
  m.name = hasAttr(n, "id") ? attr(n, "id") : "bsdf-line" + std::to_string(n.file->line(n.xml.offset_debug()));
  return m_bsdfs.emplace(n.xml.internal_object(), m).first->second;
}

float MitsubaLoader::iorOf(Props& p, const std::string& name, const std::string& def) {
  if (!p.has(name)) return iorTable().at(def);
  // Mitsuba accepts <float> or <string>: a name is looked up, a number taken as it is.
  if (!p.isString(name)) return p.getFloat(name, 1.0f, 1.0f, 10.0f);
  const std::string s = p.getString(name, "");
  std::string lower = s;
  std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  const auto it = iorTable().find(lower);
  if (it == iorTable().end()) {
    std::vector<double> v;
    if (parseNumbers(s, v) && v.size() == 1 && v[0] >= 1.0) return float(v[0]);
    fail(p.node(), "unknown index of refraction '" + s + "' for " + name + " (Mitsuba's named ones: bk7, air, water, diamond, ...)");
  }
  return it->second;
}

void MitsubaLoader::roughness(Props& p, Material& m) {
  if (p.has("alpha_u") || p.has("alpha_v")) {
    const float u = p.getFloat("alpha_u", 0.1f, 1e-4f, 1.0f), v = p.getFloat("alpha_v", 0.1f, 1e-4f, 1.0f);
    if (u != v) fail(p.node(), "anisotropic roughness (alpha_u != alpha_v): voxcone's microfacets are isotropic");
    if (p.has("alpha")) fail(p.node(), "give alpha or alpha_u/alpha_v, not both");
    m.roughness = u;
  } else {
    m.roughness = p.getFloat("alpha", 0.1f, 1e-4f, 1.0f);
  }
  // Mitsuba's rough BSDFs default to Beckmann.
  const std::string dist = p.getString("distribution", "beckmann");
  if (dist == "beckmann") m.distribution = MicrofacetDistribution::Beckmann;
  else if (dist == "ggx") m.distribution = MicrofacetDistribution::GGX;
  else fail(p.node(), "unknown distribution '" + dist + "' (beckmann, ggx)");
  // voxcone always samples visible normals; Mitsuba's switch changes only the noise.
  p.getBool("sample_visible", true);
}

void MitsubaLoader::diffuseAlbedo(Props& p, Material& m, const std::string& name) {
  m.albedo = p.getColor(name, Vec3(0.5f), 0.0f, 1.0f);
  for (const Node& t : p.takeObjects("texture")) {
    if (!hasAttr(t, "name") || attr(t, "name") != name)
      fail(t, "a texture of " + p.type() + " must be its '" + name + "' (voxcone textures the diffuse albedo only)");
    if (p.has(name) || m.albedoTexture >= 0) fail(t, "parameter '" + name + "' given twice");
    m.albedoTexture = bitmapTexture(resolve(t, "texture"));
    m.albedo = Vec3(1.0f);
  }
}

Material MitsubaLoader::parseBsdf(const Node& n, bool insideTwoSided) {
  allowAttrs(n, {"type", "id", "name"});
  Props p(*this, n);
  const std::string& type = p.type();
  Material m;
  m.twoSided = false;  // Mitsuba's BSDFs are one-sided unless wrapped in twosided
  if (type == "twosided") {
    if (insideTwoSided) fail(n, "twosided inside twosided");
    std::vector<Node> inner = p.takeObjects("bsdf");
    if (inner.size() != 1)
      fail(n, inner.empty() ? "twosided needs one nested <bsdf>"
                            : "twosided with two different BSDFs (front and back): voxcone's materials have one");
    const Node b = resolve(inner[0], "bsdf");
    m = parseBsdf(b, true);
    if (m.isTransmissive()) fail(n, "twosided around a transmissive BSDF (Mitsuba refuses it too)");
    m.twoSided = true;
  } else if (type == "diffuse") {
    m.type = MaterialType::Lambertian;
    diffuseAlbedo(p, m, "reflectance");
  } else if (type == "plastic" || type == "roughplastic") {
    m.type = type == "plastic" ? MaterialType::Plastic : MaterialType::RoughPlastic;
    diffuseAlbedo(p, m, "diffuse_reflectance");
    m.specular = p.getColor("specular_reflectance", Vec3(1.0f), 0.0f, 1.0f);
    // Mitsuba's defaults: int_ior polypropylene, ext_ior air.
    m.ior = iorOf(p, "int_ior", "polypropylene") / iorOf(p, "ext_ior", "air");
    if (!(m.ior >= 1.0001f && m.ior <= 10.0f))
      fail(n, "int_ior / ext_ior = " + std::to_string(m.ior) + ": voxcone's coats need a ratio in [1.0001, 10]");
    m.coatNonlinear = p.getBool("nonlinear", false);
    if (m.type == MaterialType::RoughPlastic) roughness(p, m);
  } else if (type == "conductor" || type == "roughconductor") {
    const std::string preset = p.getString("material", "none");
    if (p.has("eta") || p.has("k") || preset == "none") {
      if (preset != "none") fail(n, "give eta/k or a material, not both");
      // Mitsuba's defaults: eta 0, k 1, a perfect mirror.
      m.eta = p.getColor("eta", Vec3(0.0f));
      m.k = p.getColor("k", Vec3(1.0f));
    } else {
      const auto it = conductorTable().find(preset);
      if (it == conductorTable().end())
        fail(n, "conductor material '" + preset + "' is not among voxcone's RGB presets (Ag, Al, Au, Cr, Cu, W); give eta and k");
      m.eta = it->second.eta;
      m.k = it->second.k;
    }
    m.specular = p.getColor("specular_reflectance", Vec3(1.0f), 0.0f, 1.0f);
    if (type == "conductor") {
      // eta 0, k 1 reflects everything at every angle: voxcone's mirror says so exactly.
      const bool mirror = !p.has("eta") && !p.has("k") && preset == "none";
      m.type = mirror ? MaterialType::Mirror : MaterialType::Conductor;
    } else {
      m.type = MaterialType::RoughConductor;
      roughness(p, m);
    }
  } else if (type == "dielectric" || type == "roughdielectric" || type == "thindielectric") {
    m.type = type == "dielectric"       ? MaterialType::Dielectric
             : type == "thindielectric" ? MaterialType::ThinDielectric
                                        : MaterialType::RoughDielectric;
    // Mitsuba's defaults: int_ior bk7, ext_ior air.
    const float intIor = iorOf(p, "int_ior", "bk7"), extIor = iorOf(p, "ext_ior", "air");
    m.ior = intIor / extIor;
    if (!(m.ior >= 1.0001f && m.ior <= 10.0f))
      fail(n, "int_ior / ext_ior = " + std::to_string(m.ior) + ": voxcone's dielectrics need a ratio in [1.0001, 10] (the denser side inside)");
    const Vec3 r = p.getColor("specular_reflectance", Vec3(1.0f), 0.0f, 1.0f);
    const Vec3 t = p.getColor("specular_transmittance", Vec3(1.0f), 0.0f, 1.0f);
    if (r != t) fail(n, "specular_reflectance differs from specular_transmittance: voxcone's dielectric has one tint");
    m.specular = r;
    m.twoSided = true;  // both sides are the model; the flag is ignored for transmissive materials
    if (m.type == MaterialType::RoughDielectric) roughness(p, m);
  } else {
    fail(n, "unsupported BSDF plugin '" + type + "' (voxcone maps diffuse, plastic, roughplastic, twosided, "
            "dielectric, roughdielectric, thindielectric, conductor, roughconductor)");
  }
  p.finish();
  return m;
}

}  // namespace mitsuba_xml
}  // namespace voxcone

// Mitsuba 3 XML scene loader (pugixml). Every element and every parameter is checked, as the
// JSON loader checks its keys: what voxcone cannot render as Mitsuba would is a SceneError
// naming the element, the file and the line, never a silent approximation. The conventions
// followed are Mitsuba 3's (src/core/xml.cpp, src/render/bsdf plugins, src/sensors/perspective.cpp,
// src/core/transform.h), cited where they matter.

#include "voxcone/scene/mitsuba.h"

#include "scene_build.h"
#include "voxcone/core/error.h"
#include "voxcone/scene/mesh.h"

#include <pugixml.hpp>

#include <glm/gtc/matrix_transform.hpp>

#include <algorithm>
#include <array>
#include <cctype>
#include <cfloat>
#include <cstdlib>
#include <deque>
#include <filesystem>
#include <fstream>
#include <memory>
#include <set>
#include <sstream>

namespace voxcone {

bool isMitsubaScenePath(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return ext == ".xml";
}

namespace {

namespace fs = std::filesystem;

/// One XML file of the scene (the root or an include) and its line starts, for messages.
struct XmlFile {
  std::string path;   ///< as named in messages
  std::string dir;    ///< resolves the file names it contains
  std::string text;
  pugi::xml_document doc;
  std::vector<size_t> lineStarts;

  void indexLines() {
    lineStarts.push_back(0);
    for (size_t i = 0; i < text.size(); ++i)
      if (text[i] == '\n') lineStarts.push_back(i + 1);
  }
  /// 1-based line of byte `offset` (pugixml's offset_debug()).
  int line(ptrdiff_t offset) const {
    if (offset < 0) return 0;
    return int(std::upper_bound(lineStarts.begin(), lineStarts.end(), size_t(offset)) - lineStarts.begin());
  }
};

/// An element with the file it came from.
struct Node {
  pugi::xml_node xml;
  const XmlFile* file = nullptr;
  std::string tag() const { return xml.name(); }
};

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

std::string trim(const std::string& s) {
  size_t a = 0, b = s.size();
  while (a < b && std::isspace(static_cast<unsigned char>(s[a]))) ++a;
  while (b > a && std::isspace(static_cast<unsigned char>(s[b - 1]))) --b;
  return s.substr(a, b - a);
}

/// Largest absolute component, in double (before any conversion to float).
double largest(const DVec3& v) { return std::max({std::abs(v.x), std::abs(v.y), std::abs(v.z)}); }

/// Numbers separated by commas and/or white space (Mitsuba's lists: "1, 2, 3" or "1 2 3").
bool parseNumbers(const std::string& text, std::vector<double>& out) {
  out.clear();
  const char* p = text.c_str();
  while (*p) {
    while (*p && (std::isspace(static_cast<unsigned char>(*p)) || *p == ',')) ++p;
    if (!*p) break;
    char* end = nullptr;
    const double v = std::strtod(p, &end);
    // Every value ends up in a float: beyond FLT_MAX the conversion is undefined.
    if (end == p || !std::isfinite(v) || std::abs(v) > double(FLT_MAX)) return false;
    out.push_back(v);
    p = end;
  }
  return true;
}

class MitsubaLoader;

/// The parameters of one plugin element (`<shape type="obj">` ...): its named children, read
/// once each; finish() reports any not read (pbrt-v4's ReportUnused, as the JSON loader).
class Props {
public:
  Props(MitsubaLoader& loader, const Node& plugin);

  const Node& node() const { return m_node; }
  const std::string& type() const { return m_type; }
  bool has(const std::string& name) const { return m_named.count(name) != 0; }

  float getFloat(const std::string& name, float def, float lo = -kInf, float hi = kInf);
  int getInt(const std::string& name, int def, int lo, int hi);
  bool getBool(const std::string& name, bool def);
  std::string getString(const std::string& name, const std::string& def, bool required = false);
  /// A colour: `rgb` (one or three values), `spectrum` with one constant value, or `float`.
  Vec3 getColor(const std::string& name, const Vec3& def, float lo = 0.0f, float hi = kInf);
  /// A `point` or `vector` (x/y/z attributes or value="x, y, z").
  Vec3 getPoint(const std::string& name, const Vec3& def, bool required = false);
  /// True when parameter `name` is given as a <string>.
  bool isString(const std::string& name) const {
    const auto it = m_named.find(name);
    return it != m_named.end() && it->second.tag() == "string";
  }
  /// A `transform` (identity when absent). `onlyLookat` is set when the transform is a single
  /// `lookat`, whose origin, target and up the loader then holds as given (m_lookTarget, m_lookUp).
  glm::dmat4 getTransform(const std::string& name, bool* onlyLookat = nullptr);

  /// Nested plugins and references, in order (each returned once; unread ones are reported).
  std::vector<Node> takeObjects(const std::string& tag);
  void finish();

private:
  Node named(const std::string& name, std::initializer_list<const char*> tags);

  MitsubaLoader& m_loader;
  Node m_node;
  std::string m_type;
  std::map<std::string, Node> m_named;
  std::vector<Node> m_objects;
  std::set<std::string> m_used;
  std::set<const void*> m_usedObjects;
};

class MitsubaLoader {
public:
  MitsubaLoader(const std::string& origin, const SceneParameters& parameters) : m_origin(origin), m_params(parameters) {
    m_scene.sourcePath = origin;
  }

  Scene load(const std::string& text, const std::string& baseDir) {
    const XmlFile& root = parseFile(m_origin, baseDir, text);
    const pugi::xml_node scene = root.doc.document_element();
    Node sceneNode{scene, &root};
    if (std::string(scene.name()) != "scene") fail(sceneNode, "the root element must be <scene>");
    if (!scene.attribute("version")) fail(sceneNode, "<scene> needs a version attribute (version=\"3.0.0\")");
    for (const pugi::xml_attribute& a : scene.attributes())
      if (std::string(a.name()) != "version") fail(sceneNode, "unknown attribute '" + std::string(a.name()) + "'");
    std::vector<Node> top;
    std::set<std::string> includeStack{fs::weakly_canonical(fs::path(baseDir) / fs::path(m_origin).filename()).string()};
    collect(sceneNode, top, includeStack);
    for (const Node& n : top) registerIds(n);
    bool haveSensor = false, haveIntegrator = false;
    for (const Node& n : top) {
      const std::string tag = n.tag();
      if (tag == "default") continue;
      if (tag == "shape") {
        parseShape(n);
      } else if (tag == "bsdf") {
        bsdfMaterial(n);  // checked even when unused: an unsupported plugin is an error anyway
      } else if (tag == "emitter") {
        parseTopEmitter(n);
      } else if (tag == "sensor") {
        if (haveSensor) fail(n, "a second sensor: voxcone renders one camera");
        haveSensor = true;
        parseSensor(n);
      } else if (tag == "integrator") {
        if (haveIntegrator) fail(n, "a second integrator");
        haveIntegrator = true;
        parseIntegrator(n);
      } else if (tag == "texture") {
        // Read where a BSDF refers to it (by id).
      } else if (tag == "medium" || tag == "volume" || tag == "phase") {
        fail(n, "unsupported element: voxcone has no " + tag + "s");
      } else {
        fail(n, "unsupported element <" + tag + "> in <scene>");
      }
    }
    if (!haveSensor) fail(sceneNode, "the scene has no <sensor>: voxcone needs a perspective camera");
    detail::finishScene(m_scene, m_origin);
    return std::move(m_scene);
  }

  // ---------------------------------------------------------------------------------------
  // Errors and attributes

  /// "FILE: line N: <tag type="t" id="x">: what"
  [[noreturn]] void fail(const Node& n, const std::string& what) const {
    std::string el = "<" + n.tag();
    for (const char* a : {"type", "name", "id"})
      if (n.xml.attribute(a)) el += std::string(" ") + a + "=\"" + n.xml.attribute(a).value() + "\"";
    el += ">";
    throw SceneError(n.file ? n.file->path : m_origin, "line " + std::to_string(n.file ? n.file->line(n.xml.offset_debug()) : 0),
                     el + ": " + what);
  }

  /// Attribute `name` of `n` with $parameters substituted (Mitsuba 3 substitutes every attribute).
  std::string attr(const Node& n, const char* name, bool required = true) const {
    const pugi::xml_attribute a = n.xml.attribute(name);
    if (!a) {
      if (required) fail(n, std::string("missing attribute '") + name + "'");
      return "";
    }
    return substitute(n, a.value());
  }
  bool hasAttr(const Node& n, const char* name) const { return bool(n.xml.attribute(name)); }

  std::string substitute(const Node& n, const std::string& value) const {
    std::string out;
    for (size_t i = 0; i < value.size(); ++i) {
      if (value[i] != '$') {
        out += value[i];
        continue;
      }
      size_t j = i + 1;
      while (j < value.size() && (std::isalnum(static_cast<unsigned char>(value[j])) || value[j] == '_')) ++j;
      const std::string key = value.substr(i + 1, j - i - 1);
      if (key.empty()) fail(n, "a '$' without a parameter name in \"" + value + "\"");
      const auto it = m_params.find(key);
      if (it == m_params.end())
        fail(n, "undefined parameter $" + key + " (give it with <default name=\"" + key + "\" value=...> or -D " + key + "=...)");
      out += it->second;
      i = j - 1;
    }
    return out;
  }

  /// Only these attributes may appear on `n`.
  void allowAttrs(const Node& n, std::initializer_list<const char*> names) const {
    for (const pugi::xml_attribute& a : n.xml.attributes()) {
      bool ok = false;
      for (const char* k : names) ok = ok || std::string(a.name()) == k;
      if (!ok) fail(n, "unknown attribute '" + std::string(a.name()) + "'");
    }
  }

  /// A transformed point as float; a coordinate beyond float's range is an error.
  Vec3 toFloat(const Node& n, const DVec3& v) const {
    if (!(largest(v) <= double(FLT_MAX))) fail(n, "a transformed coordinate is beyond float's range");
    return Vec3(v);
  }

  double number(const Node& n, const std::string& text) const {
    std::vector<double> v;
    if (!parseNumbers(text, v) || v.size() != 1) fail(n, "expected one number, got \"" + text + "\"");
    return v[0];
  }
  std::vector<double> numbers(const Node& n, const std::string& text) const {
    std::vector<double> v;
    if (!parseNumbers(text, v)) fail(n, "expected numbers, got \"" + text + "\"");
    return v;
  }

  /// A point/vector: value="x, y, z" or x/y/z attributes (missing ones are `def`).
  DVec3 vec3Of(const Node& n, double def) const {
    if (hasAttr(n, "value")) {
      if (hasAttr(n, "x") || hasAttr(n, "y") || hasAttr(n, "z")) fail(n, "give value or x/y/z, not both");
      const std::vector<double> v = numbers(n, attr(n, "value"));
      if (v.size() == 1) return DVec3(v[0]);
      if (v.size() != 3) fail(n, "expected 3 numbers");
      return DVec3(v[0], v[1], v[2]);
    }
    DVec3 r(def);
    if (hasAttr(n, "x")) r.x = number(n, attr(n, "x"));
    if (hasAttr(n, "y")) r.y = number(n, attr(n, "y"));
    if (hasAttr(n, "z")) r.z = number(n, attr(n, "z"));
    return r;
  }

  // ---------------------------------------------------------------------------------------
  // Files, includes, defaults, ids

  const XmlFile& parseFile(const std::string& path, const std::string& dir, const std::string& text) {
    m_files.emplace_back();
    XmlFile& f = m_files.back();
    f.path = path;
    f.dir = dir.empty() ? "." : dir;
    f.text = text;
    f.indexLines();
    // The root file and each include, for the sidecar's hashes (a scene parsed from a string
    // names no file).
    std::error_code ec;
    if (fs::is_regular_file(path, ec)) m_scene.inputFiles.push_back(path);
    const pugi::xml_parse_result res = f.doc.load_buffer(f.text.data(), f.text.size(), pugi::parse_default, pugi::encoding_utf8);
    if (!res)
      throw SceneError(path, "line " + std::to_string(f.line(res.offset)), std::string("malformed XML: ") + res.description());
    return f;
  }

  /// The scene's top-level elements in order, includes expanded in place and defaults applied.
  void collect(const Node& scene, std::vector<Node>& out, std::set<std::string>& stack) {
    for (pugi::xml_node c = scene.xml.first_child(); c; c = c.next_sibling()) {
      if (c.type() != pugi::node_element) continue;
      const Node n{c, scene.file};
      const std::string tag = n.tag();
      if (tag == "default") {
        allowAttrs(n, {"name", "value"});
        const std::string name = attr(n, "name");
        if (name.empty()) fail(n, "empty parameter name");
        // -D and earlier defaults win: a default only fills a parameter not yet given.
        if (!m_params.count(name)) m_params[name] = attr(n, "value");
        continue;
      }
      if (tag == "include") {
        allowAttrs(n, {"filename"});
        fs::path p = attr(n, "filename");
        if (p.is_relative()) p = fs::path(n.file->dir) / p;
        const std::string key = fs::weakly_canonical(p).string();
        if (stack.count(key)) fail(n, "include cycle: " + p.string() + " includes itself");
        std::ifstream in(p, std::ios::binary);
        if (!in) fail(n, "cannot open included file " + p.string());
        std::ostringstream ss;
        ss << in.rdbuf();
        const XmlFile& inc = parseFile(p.string(), p.parent_path().string(), ss.str());
        const Node incRoot{inc.doc.document_element(), &inc};
        if (incRoot.tag() != "scene") fail(incRoot, "an included file's root element must be <scene>");
        stack.insert(key);
        collect(incRoot, out, stack);
        stack.erase(key);
        continue;
      }
      out.push_back(n);
    }
  }

  /// Every element with an id, at any depth (Mitsuba resolves references after parsing).
  /// Scenes nest a few levels; a limit keeps hostile input from exhausting the stack.
  void registerIds(const Node& n, int depth = 0) {
    if (depth > 32) fail(n, "elements nested more than 32 deep");
    if (n.xml.attribute("id") && n.tag() != "ref") {
      const std::string id = attr(n, "id");
      const auto [it, fresh] = m_ids.emplace(id, n);
      if (!fresh) fail(n, "duplicate id '" + id + "' (first at line " + std::to_string(it->second.file->line(it->second.xml.offset_debug())) + ")");
    }
    for (pugi::xml_node c = n.xml.first_child(); c; c = c.next_sibling())
      if (c.type() == pugi::node_element) registerIds(Node{c, n.file}, depth + 1);
  }

  /// A nested plugin or a <ref id=...> to one of tag `tag`.
  Node resolve(const Node& n, const std::string& tag) const {
    if (n.tag() != "ref") {
      if (n.tag() != tag) fail(n, "expected a <" + tag + ">");
      return n;
    }
    allowAttrs(n, {"id", "name"});
    const std::string id = attr(n, "id");
    const auto it = m_ids.find(id);
    if (it == m_ids.end()) fail(n, "no element with id '" + id + "'");
    if (it->second.tag() != tag) fail(n, "id '" + id + "' names a <" + it->second.tag() + ">, not a <" + tag + ">");
    return it->second;
  }

  // ---------------------------------------------------------------------------------------
  // BSDFs

  /// The index in m_scene.textures of a <texture type="bitmap">: its filename (relative to its
  /// file's folder), 8-bit files decoded from sRGB, bilinear, repeating, no to_uv.
  int32_t bitmapTexture(const Node& n) {
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

  /// The material a <bsdf> describes (parsed once per element).
  const Material& bsdfMaterial(const Node& n) {
    const auto it = m_bsdfs.find(n.xml.internal_object());
    if (it != m_bsdfs.end()) return it->second;
    Material m = parseBsdf(n, false);
    m.name = hasAttr(n, "id") ? attr(n, "id") : "bsdf-line" + std::to_string(n.file->line(n.xml.offset_debug()));
    return m_bsdfs.emplace(n.xml.internal_object(), m).first->second;
  }

  /// Index of refraction from a float or a name of Mitsuba's table.
  float iorOf(Props& p, const std::string& name, const std::string& def) {
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

  void roughness(Props& p, Material& m) {
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

  /// A diffuse albedo `name`: a colour or a bitmap texture (then the albedo factor is 1).
  void diffuseAlbedo(Props& p, Material& m, const std::string& name) {
    m.albedo = p.getColor(name, Vec3(0.5f), 0.0f, 1.0f);
    for (const Node& t : p.takeObjects("texture")) {
      if (!hasAttr(t, "name") || attr(t, "name") != name)
        fail(t, "a texture of " + p.type() + " must be its '" + name + "' (voxcone textures the diffuse albedo only)");
      if (p.has(name) || m.albedoTexture >= 0) fail(t, "parameter '" + name + "' given twice");
      m.albedoTexture = bitmapTexture(resolve(t, "texture"));
      m.albedo = Vec3(1.0f);
    }
  }

  Material parseBsdf(const Node& n, bool insideTwoSided) {
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

  // ---------------------------------------------------------------------------------------
  // Shapes


  /// The material of a shape: its BSDF (Mitsuba's default: a one-sided diffuse of reflectance
  /// 0.5) with the area emitter's radiance; one Material per (BSDF, radiance) pair.
  uint32_t shapeMaterial(const Node* bsdf, const Vec3& radiance) {
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

  /// Mitsuba's recompute_vertex_normals (Mitsuba 3 src/render/mesh.cpp): face normals summed at
  /// each vertex weighted by the corner angle (Thuermer & Wuethrich 1998), normalized.
  static std::vector<Vec3> angleWeightedNormals(const std::vector<Vec3>& pos, const std::vector<UVec3>& tris) {
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

  void parseShape(const Node& n) {
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

  // ---------------------------------------------------------------------------------------
  // Emitters, sensor, integrator

  void parseTopEmitter(const Node& n) {
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

  /// Mitsuba 3's parse_fov (src/render/sensor.cpp): the x field of view in degrees.
  double fovX(const Node& n, double fov, const std::string& axis, double aspect) const {
    const auto toX = [&](double f) { return 2.0 * std::atan(std::tan(0.5 * glm::radians(f)) * aspect); };
    if (axis == "x") return glm::radians(fov);
    if (axis == "y") return toX(fov);
    if (axis == "diagonal") {
      const double diagonal = 2.0 * std::tan(0.5 * glm::radians(fov));
      const double width = diagonal / std::sqrt(1.0 + 1.0 / (aspect * aspect));
      return 2.0 * std::atan(0.5 * width);
    }
    if (axis == "smaller") return aspect > 1.0 ? toX(fov) : glm::radians(fov);
    if (axis == "larger") return aspect < 1.0 ? toX(fov) : glm::radians(fov);
    fail(n, "fov_axis must be x, y, diagonal, smaller or larger, not '" + axis + "'");
  }

  void parseSensor(const Node& n) {
    allowAttrs(n, {"type", "id", "name"});
    Props p(*this, n);
    if (p.type() != "perspective") fail(n, "unsupported sensor plugin '" + p.type() + "' (voxcone maps perspective)");
    RenderSettings& s = m_scene.render;
    // Film first: the field of view's axis depends on the aspect ratio. Mitsuba's hdrfilm
    // default is 768 x 576.
    s.width = 768;
    s.height = 576;
    for (const Node& f : p.takeObjects("film")) {
      allowAttrs(f, {"type", "id", "name"});
      Props fp(*this, f);
      if (fp.type() != "hdrfilm") fail(f, "unsupported film plugin '" + fp.type() + "' (voxcone maps hdrfilm)");
      s.width = fp.getInt("width", 768, 1, 32768);
      s.height = fp.getInt("height", 576, 1, 32768);
      // Output details voxcone decides itself (it writes float RGB EXR, PNG and a sidecar).
      fp.getString("file_format", "openexr");
      const std::string pf = fp.getString("pixel_format", "rgb");
      if (pf != "rgb" && pf != "rgba") fail(f, "pixel_format '" + pf + "': voxcone writes RGB");
      fp.getString("component_format", "float16");
      // voxcone's only pixel filter is the one-pixel box. Without an rfilter Mitsuba uses a
      // Gaussian (stddev 0.5 pixel): voxcone renders box then (README says so); an explicit
      // other filter is an error.
      for (const Node& r : fp.takeObjects("rfilter")) {
        allowAttrs(r, {"type", "id", "name"});
        Props rp(*this, r);
        if (rp.type() != "box")
          fail(r, "unsupported rfilter '" + rp.type() + "': voxcone's pixel filter is the box of one pixel "
                  "(use <rfilter type=\"box\"/>)");
        rp.finish();
      }
      fp.finish();
    }
    for (const Node& sm : p.takeObjects("sampler")) {
      allowAttrs(sm, {"type", "id", "name"});
      Props sp(*this, sm);
      const std::string& t = sp.type();
      // Mitsuba's samplers differ in their noise only: independent is voxcone's independent,
      // the stratified and low-discrepancy ones voxcone's Sobol (core/sampler.h).
      if (t == "independent") s.sampler = SamplerKind::Independent;
      else if (t == "ldsampler" || t == "stratified" || t == "multijitter" || t == "orthogonal") s.sampler = SamplerKind::Sobol;
      else fail(sm, "unsupported sampler plugin '" + t + "'");
      s.spp = sp.getInt("sample_count", 4, 1, 1 << 24);
      s.seed = uint64_t(sp.getInt("seed", 0, 0, INT32_MAX));
      sp.getBool("jitter", true);
      sp.finish();
    }
    const double aspect = double(s.width) / double(s.height);
    double fovYDeg = 0.0;
    if (p.has("fov") && p.has("focal_length")) fail(n, "give fov or focal_length, not both");
    std::string axis = p.getString("fov_axis", "x");
    std::transform(axis.begin(), axis.end(), axis.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    double fov;
    if (p.has("focal_length")) {
      // Mitsuba: a 35 mm film's diagonal (sqrt(36^2 + 24^2) mm) at this focal length.
      std::string f = p.getString("focal_length", "50mm");
      if (f.size() > 2 && f.substr(f.size() - 2) == "mm") f = f.substr(0, f.size() - 2);
      const double mm = number(n, f);
      if (!(mm > 0.0)) fail(n, "focal_length must be positive");
      fov = glm::degrees(2.0 * std::atan(std::sqrt(36.0 * 36.0 + 24.0 * 24.0) / (2.0 * mm)));
      axis = "diagonal";
    } else {
      fov = p.getFloat("fov", 0.0f, 1e-4f, 179.9f);
      if (!p.has("fov")) fail(n, "a perspective sensor needs fov (or focal_length)");
    }
    // The vertical angle as voxcone's camera takes it; given on the y axis it is kept exactly.
    if (axis == "y" || (axis == "smaller" && aspect > 1.0) || (axis == "larger" && aspect < 1.0))
      fovYDeg = fov;
    else
      fovYDeg = glm::degrees(2.0 * std::atan(std::tan(0.5 * fovX(n, fov, axis, aspect)) / aspect));
    if (!(fovYDeg >= 0.01 && fovYDeg <= 179.0))
      fail(n, "vertical field of view " + std::to_string(fovYDeg) + " degrees: voxcone's camera takes [0.01, 179]");
    // voxcone's rays start at the pinhole and have no far limit: near_clip and far_clip only
    // cut geometry nearer or farther than them in Mitsuba (README says so).
    p.getFloat("near_clip", 0.01f, 0.0f);
    p.getFloat("far_clip", 1e4f, 0.0f);
    bool onlyLookat = false;
    const glm::dmat4 xf = p.getTransform("to_world", &onlyLookat);
    p.finish();

    // The camera frame. Mitsuba's perspective camera looks along local +z with local +y up
    // and maps local +x to the image's LEFT (its camera-to-sample transform scales x by -0.5,
    // src/sensors/perspective.cpp); look_at sets local x = cross(up, dir). So image right is
    // cross(dir, up), as in voxcone's Camera: the same lookat gives the same, unmirrored image.
    const DVec3 origin(xf[3]), x(xf[0]), y(xf[1]), z(xf[2]);
    const double lx = glm::length(x), ly = glm::length(y), lz = glm::length(z);
    if (!(lx > 0.0 && ly > 0.0 && lz > 0.0)) fail(n, "the sensor's to_world is singular");
    const double tol = 1e-5;
    if (std::abs(glm::dot(x, y)) > tol * lx * ly || std::abs(glm::dot(x, z)) > tol * lx * lz ||
        std::abs(glm::dot(y, z)) > tol * ly * lz || std::abs(lx - ly) > tol * lx || std::abs(lx - lz) > tol * lx)
      fail(n, "the sensor's to_world shears or scales unevenly: voxcone's pinhole camera cannot render that");
    if (glm::determinant(glm::dmat3(xf)) < 0.0)
      fail(n, "the sensor's to_world mirrors the image: voxcone's camera is not mirrored");
    if (!(largest(origin) <= detail::kMaxSceneReach))
      fail(n, "the camera lies beyond the range voxcone renders in float");
    Vec3 pos(origin), target, up;
    if (onlyLookat) {
      // Keep lookat's own target and up (the JSON camera's fields: round trips stay exact).
      target = m_lookTarget;
      up = m_lookUp;
    } else {
      target = Vec3(origin + z / lz);
      up = Vec3(y / ly);
    }
    m_scene.camera = Camera(pos, target, up, float(fovYDeg));
  }

  void parseIntegrator(const Node& n) {
    allowAttrs(n, {"type", "id", "name"});
    Props p(*this, n);
    const std::string& t = p.type();
    RenderSettings& s = m_scene.render;
    // voxcone's own methods, a voxcone extension Mitsuba does not load (written by convert).
    if (t == "path" || t == "voxcone" || t == "pm" || t == "whitted") {
      s.method = t;
    } else {
      fail(n, "unsupported integrator plugin '" + t + "' (voxcone maps path; voxcone, pm and whitted are voxcone's)");
    }
    // Mitsuba's max_depth: the longest path in segments, 1 = emitters seen directly, 2 =
    // direct lighting, -1 = unbounded (Mitsuba 3 src/integrators/path.cpp: a vertex continues
    // while depth + 1 < max_depth). voxcone's maxDepth counts the same (path.cpp breaks when
    // depth + 1 >= maxDepth), so the number carries over; -1 becomes voxcone's largest, 1024.
    const int depth = p.getInt("max_depth", -1, -1, 1024);
    if (depth == 0) fail(n, "max_depth 0 renders nothing; voxcone needs at least 1");
    s.maxDepth = depth < 0 ? 1024 : depth;
    if (p.has("rr_depth"))
      fail(n, "rr_depth: voxcone's path integrator takes it as an option (voxcone render --options '{\"rr_depth\": N}')");
    if (p.getBool("hide_emitters", false)) fail(n, "hide_emitters: voxcone always shows emitters seen directly");
    if (t == "voxcone" || t == "pm") {
      s.photons = uint64_t(p.getInt("photons", 0, 0, INT32_MAX));
      s.causticPhotons = uint64_t(p.getInt("caustic_photons", 0, 0, INT32_MAX));
    }
    p.finish();
  }

  // Parsing transforms (Props::getTransform) records lookat's target and up here.
  Vec3 m_lookTarget{0.0f}, m_lookUp{0.0f, 1.0f, 0.0f};

private:
  std::string m_origin;
  SceneParameters m_params;
  std::deque<XmlFile> m_files;
  std::map<std::string, Node> m_ids;
  std::map<const void*, Material> m_bsdfs;
  std::map<std::pair<const void*, std::array<float, 3>>, uint32_t> m_shapeMaterials;
  std::set<std::string> m_materialNames;
  Scene m_scene;

  friend class Props;
};

// -------------------------------------------------------------------------------------------
// Props

Props::Props(MitsubaLoader& loader, const Node& plugin) : m_loader(loader), m_node(plugin) {
  m_type = loader.attr(plugin, "type");
  for (pugi::xml_node c = plugin.xml.first_child(); c; c = c.next_sibling()) {
    if (c.type() != pugi::node_element) continue;
    const Node n{c, plugin.file};
    const std::string tag = n.tag();
    static const std::set<std::string> values = {"float", "integer", "boolean", "string", "rgb", "spectrum", "point", "vector", "transform"};
    static const std::set<std::string> objects = {"bsdf", "emitter", "film", "sampler", "rfilter", "ref", "shape",
                                                  "texture", "medium", "sensor", "integrator", "volume", "phase"};
    if (values.count(tag)) {
      const std::string name = loader.attr(n, "name");
      if (!m_named.emplace(name, n).second) loader.fail(n, "parameter '" + name + "' given twice");
    } else if (objects.count(tag)) {
      if (tag == "medium" || tag == "volume" || tag == "phase") loader.fail(n, "unsupported: voxcone has no participating media");
      m_objects.push_back(n);
    } else {
      loader.fail(n, "unknown element <" + tag + ">");
    }
  }
}

Node Props::named(const std::string& name, std::initializer_list<const char*> tags) {
  const auto it = m_named.find(name);
  if (it == m_named.end()) return Node{};
  m_used.insert(name);
  const std::string tag = it->second.tag();
  for (const char* t : tags)
    if (tag == t) return it->second;
  std::string want;
  for (const char* t : tags) want += std::string(want.empty() ? "" : " or ") + "<" + t + ">";
  m_loader.fail(it->second, "parameter '" + name + "' of " + m_type + " must be " + want);
}

float Props::getFloat(const std::string& name, float def, float lo, float hi) {
  const Node n = named(name, {"float", "integer"});
  if (!n.xml) return def;
  m_loader.allowAttrs(n, {"name", "value"});
  const double v = m_loader.number(n, m_loader.attr(n, "value"));
  if (v < lo || v > hi) {
    std::ostringstream os;
    os << name << " = " << v << " is outside [" << lo << ", " << hi << "]";
    m_loader.fail(n, os.str());
  }
  return float(v);
}

int Props::getInt(const std::string& name, int def, int lo, int hi) {
  const Node n = named(name, {"integer"});
  if (!n.xml) return def;
  m_loader.allowAttrs(n, {"name", "value"});
  const std::string text = trim(m_loader.attr(n, "value"));
  char* end = nullptr;
  const long long v = std::strtoll(text.c_str(), &end, 10);
  if (text.empty() || *end != '\0') m_loader.fail(n, "expected an integer, got \"" + text + "\"");
  if (v < lo || v > hi)
    m_loader.fail(n, name + " = " + text + " is outside [" + std::to_string(lo) + ", " + std::to_string(hi) + "]");
  return int(v);
}

bool Props::getBool(const std::string& name, bool def) {
  const Node n = named(name, {"boolean"});
  if (!n.xml) return def;
  m_loader.allowAttrs(n, {"name", "value"});
  std::string v = trim(m_loader.attr(n, "value"));
  std::transform(v.begin(), v.end(), v.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  if (v == "true") return true;
  if (v == "false") return false;
  m_loader.fail(n, "expected true or false, got \"" + v + "\"");
}

std::string Props::getString(const std::string& name, const std::string& def, bool required) {
  const auto it = m_named.find(name);
  if (it == m_named.end()) {
    if (required) m_loader.fail(m_node, "missing parameter '" + name + "'");
    return def;
  }
  const Node n = named(name, {"string"});
  m_loader.allowAttrs(n, {"name", "value"});
  return m_loader.attr(n, "value");
}

Vec3 Props::getColor(const std::string& name, const Vec3& def, float lo, float hi) {
  const Node n = named(name, {"rgb", "spectrum", "float"});
  if (!n.xml) return def;
  m_loader.allowAttrs(n, {"name", "value"});
  const std::string text = m_loader.attr(n, "value");
  std::vector<double> v;
  if (n.tag() == "spectrum" && text.find(':') != std::string::npos)
    m_loader.fail(n, "a spectrum of wavelength:value pairs: voxcone renders RGB (give one constant value or an <rgb>)");
  if (!parseNumbers(text, v) || v.empty()) m_loader.fail(n, "expected numbers, got \"" + text + "\"");
  if (n.tag() != "rgb" && v.size() != 1) m_loader.fail(n, "expected one value (an <rgb> takes three)");
  if (v.size() != 1 && v.size() != 3) m_loader.fail(n, "expected one or three values");
  const Vec3 c = v.size() == 1 ? Vec3(float(v[0])) : Vec3(float(v[0]), float(v[1]), float(v[2]));
  for (int i = 0; i < 3; ++i)
    if (!(c[i] >= lo && c[i] <= hi)) {
      std::ostringstream os;
      os << name << " component " << i << " = " << c[i] << " is outside [" << lo << ", " << hi << "]";
      m_loader.fail(n, os.str());
    }
  return c;
}

Vec3 Props::getPoint(const std::string& name, const Vec3& def, bool required) {
  const Node n = named(name, {"point", "vector"});
  if (!n.xml) {
    if (required) m_loader.fail(m_node, "missing parameter '" + name + "'");
    return def;
  }
  m_loader.allowAttrs(n, {"name", "value", "x", "y", "z"});
  return Vec3(m_loader.vec3Of(n, 0.0));
}

glm::dmat4 Props::getTransform(const std::string& name, bool* onlyLookat) {
  const Node n = named(name, {"transform"});
  if (onlyLookat) *onlyLookat = false;
  if (!n.xml) return glm::dmat4(1.0);
  m_loader.allowAttrs(n, {"name"});
  // Mitsuba 3 (src/core/xml.cpp): each operation multiplies from the left, so the first one
  // listed is applied first.
  glm::dmat4 m(1.0);
  int ops = 0;
  bool lookat = false;
  for (pugi::xml_node c = n.xml.first_child(); c; c = c.next_sibling()) {
    if (c.type() != pugi::node_element) continue;
    const Node op{c, n.file};
    const std::string tag = op.tag();
    ++ops;
    glm::dmat4 t(1.0);
    if (tag == "translate") {
      m_loader.allowAttrs(op, {"value", "x", "y", "z"});
      t = glm::translate(glm::dmat4(1.0), m_loader.vec3Of(op, 0.0));
    } else if (tag == "scale") {
      m_loader.allowAttrs(op, {"value", "x", "y", "z"});
      const DVec3 s = m_loader.vec3Of(op, 1.0);
      if (s.x == 0.0 || s.y == 0.0 || s.z == 0.0) m_loader.fail(op, "scale by zero");
      t = glm::scale(glm::dmat4(1.0), s);
    } else if (tag == "rotate") {
      m_loader.allowAttrs(op, {"value", "x", "y", "z", "angle"});
      const DVec3 axis = m_loader.vec3Of(op, 0.0);
      if (glm::length(axis) == 0.0) m_loader.fail(op, "rotation axis is zero");
      const double angle = m_loader.number(op, m_loader.attr(op, "angle"));
      // Right-handed rotation by `angle` degrees about the axis (Mitsuba's Transform4f::rotate).
      t = glm::rotate(glm::dmat4(1.0), glm::radians(angle), glm::normalize(axis));
    } else if (tag == "matrix") {
      m_loader.allowAttrs(op, {"value"});
      const std::vector<double> v = m_loader.numbers(op, m_loader.attr(op, "value"));
      if (v.size() == 16) {
        // Row-major in the file; glm is column-major.
        for (int r = 0; r < 4; ++r)
          for (int c2 = 0; c2 < 4; ++c2) t[c2][r] = v[size_t(r * 4 + c2)];
        if (t[0][3] != 0.0 || t[1][3] != 0.0 || t[2][3] != 0.0 || t[3][3] != 1.0)
          m_loader.fail(op, "a projective matrix (last row not 0 0 0 1): voxcone's transforms are affine");
      } else if (v.size() == 9) {
        for (int r = 0; r < 3; ++r)
          for (int c2 = 0; c2 < 3; ++c2) t[c2][r] = v[size_t(r * 3 + c2)];
      } else {
        m_loader.fail(op, "a matrix takes 16 values (row-major 4x4) or 9 (3x3)");
      }
    } else if (tag == "lookat") {
      m_loader.allowAttrs(op, {"origin", "target", "up"});
      const std::vector<double> o = m_loader.numbers(op, m_loader.attr(op, "origin"));
      const std::vector<double> tg = m_loader.numbers(op, m_loader.attr(op, "target"));
      const std::vector<double> u = m_loader.hasAttr(op, "up") ? m_loader.numbers(op, m_loader.attr(op, "up"))
                                                               : std::vector<double>{0.0, 1.0, 0.0};
      if (o.size() != 3 || tg.size() != 3 || u.size() != 3) m_loader.fail(op, "origin, target and up take 3 numbers each");
      const DVec3 origin(o[0], o[1], o[2]), target(tg[0], tg[1], tg[2]), up(u[0], u[1], u[2]);
      // Mitsuba's Transform4f::look_at: columns left = cross(up, dir), new_up = cross(dir,
      // left), dir, origin.
      const DVec3 d = target - origin;
      if (glm::length(d) == 0.0) m_loader.fail(op, "target equals origin");
      const DVec3 dir = glm::normalize(d);
      const DVec3 l = glm::cross(up, dir);
      if (!(glm::length(l) > 1e-9 * glm::length(up))) m_loader.fail(op, "up is parallel to the view direction");
      const DVec3 left = glm::normalize(l), newUp = glm::cross(dir, left);
      t = glm::dmat4(glm::dvec4(left, 0.0), glm::dvec4(newUp, 0.0), glm::dvec4(dir, 0.0), glm::dvec4(origin, 1.0));
      m_loader.m_lookTarget = Vec3(target);
      m_loader.m_lookUp = Vec3(up);
      lookat = true;
    } else {
      m_loader.fail(op, "unknown transform operation <" + tag + "> (translate, rotate, scale, matrix, lookat)");
    }
    m = t * m;
  }
  if (onlyLookat) *onlyLookat = lookat && ops == 1;
  return m;
}

std::vector<Node> Props::takeObjects(const std::string& tag) {
  std::vector<Node> out;
  for (const Node& o : m_objects) {
    const std::string t = o.tag();
    bool match = t == tag;
    // A <ref> stands for whatever it names.
    if (t == "ref") {
      const std::string id = m_loader.attr(o, "id");
      const auto it = m_loader.m_ids.find(id);
      if (it == m_loader.m_ids.end()) m_loader.fail(o, "no element with id '" + id + "'");
      match = it->second.tag() == tag;
    }
    if (match) {
      m_usedObjects.insert(o.xml.internal_object());
      out.push_back(o);
    }
  }
  return out;
}

void Props::finish() {
  for (const auto& [name, n] : m_named)
    if (!m_used.count(name)) m_loader.fail(n, "unsupported parameter '" + name + "' of " + m_node.tag() + " '" + m_type + "'");
  for (const Node& o : m_objects)
    if (!m_usedObjects.count(o.xml.internal_object()))
      m_loader.fail(o, "unexpected <" + o.tag() + "> inside " + m_node.tag() + " '" + m_type + "'");
}

}  // namespace

Scene parseMitsubaScene(const std::string& xmlText, const std::string& origin, const std::string& baseDir,
                        const SceneParameters& parameters) {
  return MitsubaLoader(origin, parameters).load(xmlText, baseDir.empty() ? "." : baseDir);
}

Scene loadMitsubaScene(const std::string& path, const SceneParameters& parameters) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw SceneError(path, "", "cannot open scene file");
  std::ostringstream ss;
  ss << in.rdbuf();
  const std::string dir = fs::path(path).parent_path().string();
  return parseMitsubaScene(ss.str(), path, dir.empty() ? "." : dir, parameters);
}

}  // namespace voxcone

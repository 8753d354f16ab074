#pragma once
/// \file mitsuba_loader_impl.h
/// The Mitsuba 3 XML loader's internals, shared by its files: the XML files and elements, a
/// plugin's parameters (Props) and the loader (MitsubaLoader), whose parts live by what they
/// translate: mitsuba_loader.cpp (files, includes, references, attributes), mitsuba_props.cpp
/// (parameters and transforms), mitsuba_bsdf.cpp (BSDFs and textures), mitsuba_shapes.cpp
/// (shapes and emitters), mitsuba_sensor.cpp (the sensor, film, sampler and integrator).
/// Not a public header.

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
namespace mitsuba_xml {

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

/// Largest absolute component, in double (before any conversion to float).
inline double largest(const DVec3& v) { return std::max({std::abs(v.x), std::abs(v.y), std::abs(v.z)}); }

/// Numbers separated by commas and/or white space (Mitsuba's lists: "1, 2, 3" or "1 2 3").
inline bool parseNumbers(const std::string& text, std::vector<double>& out) {
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

  Scene load(const std::string& text, const std::string& baseDir);

  // ---------------------------------------------------------------------------------------
  // Errors and attributes

  /// "FILE: line N: <tag type="t" id="x">: what"
  [[noreturn]] void fail(const Node& n, const std::string& what) const;

  /// Attribute `name` of `n` with $parameters substituted (Mitsuba 3 substitutes every attribute).
  std::string attr(const Node& n, const char* name, bool required = true) const;
  bool hasAttr(const Node& n, const char* name) const { return bool(n.xml.attribute(name)); }

  std::string substitute(const Node& n, const std::string& value) const;

  /// Only these attributes may appear on `n`.
  void allowAttrs(const Node& n, std::initializer_list<const char*> names) const;

  /// A transformed point as float; a coordinate beyond float's range is an error.
  Vec3 toFloat(const Node& n, const DVec3& v) const;

  double number(const Node& n, const std::string& text) const;
  std::vector<double> numbers(const Node& n, const std::string& text) const;

  /// A point/vector: value="x, y, z" or x/y/z attributes (missing ones are `def`).
  DVec3 vec3Of(const Node& n, double def) const;

  // ---------------------------------------------------------------------------------------
  // Files, includes, defaults, ids

  const XmlFile& parseFile(const std::string& path, const std::string& dir, const std::string& text);

  /// The scene's top-level elements in order, includes expanded in place and defaults applied.
  void collect(const Node& scene, std::vector<Node>& out, std::set<std::string>& stack);

  /// Every element with an id, at any depth (Mitsuba resolves references after parsing).
  /// Scenes nest a few levels; a limit keeps hostile input from exhausting the stack.
  void registerIds(const Node& n, int depth = 0);

  /// A nested plugin or a <ref id=...> to one of tag `tag`.
  Node resolve(const Node& n, const std::string& tag) const;

  // ---------------------------------------------------------------------------------------
  // BSDFs

  /// The index in m_scene.textures of a <texture type="bitmap">: its filename (relative to its
  /// file's folder), 8-bit files decoded from sRGB, bilinear, repeating, no to_uv.
  int32_t bitmapTexture(const Node& n);

  /// The material a <bsdf> describes (parsed once per element).
  const Material& bsdfMaterial(const Node& n);

  /// Index of refraction from a float or a name of Mitsuba's table.
  float iorOf(Props& p, const std::string& name, const std::string& def);

  void roughness(Props& p, Material& m);

  /// A diffuse albedo `name`: a colour or a bitmap texture (then the albedo factor is 1).
  void diffuseAlbedo(Props& p, Material& m, const std::string& name);

  Material parseBsdf(const Node& n, bool insideTwoSided);

  // ---------------------------------------------------------------------------------------
  // Shapes


  /// The material of a shape: its BSDF (Mitsuba's default: a one-sided diffuse of reflectance
  /// 0.5) with the area emitter's radiance; one Material per (BSDF, radiance) pair.
  uint32_t shapeMaterial(const Node* bsdf, const Vec3& radiance);

  /// Mitsuba's recompute_vertex_normals (Mitsuba 3 src/render/mesh.cpp): face normals summed at
  /// each vertex weighted by the corner angle (Thuermer & Wuethrich 1998), normalized.
  static std::vector<Vec3> angleWeightedNormals(const std::vector<Vec3>& pos, const std::vector<UVec3>& tris);

  void parseShape(const Node& n);

  // ---------------------------------------------------------------------------------------
  // Emitters, sensor, integrator

  void parseTopEmitter(const Node& n);

  /// Mitsuba 3's parse_fov (src/render/sensor.cpp): the x field of view in degrees.
  double fovX(const Node& n, double fov, const std::string& axis, double aspect) const;

  void parseSensor(const Node& n);

  void parseIntegrator(const Node& n);

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

}  // namespace mitsuba_xml
}  // namespace voxcone

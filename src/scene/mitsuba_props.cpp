/// \file mitsuba_props.cpp
/// A Mitsuba 3 plugin's parameters (Props): typed reads with range checks, colours, points and
/// transforms (src/core/transform.h's conventions), and the report of parameters left unread.

#include "mitsuba_loader_impl.h"

namespace voxcone {
namespace mitsuba_xml {

namespace {

/// `s` without leading and trailing white space.
std::string trim(const std::string& s) {
  size_t a = 0, b = s.size();
  while (a < b && std::isspace(static_cast<unsigned char>(s[a]))) ++a;
  while (b > a && std::isspace(static_cast<unsigned char>(s[b - 1]))) --b;
  return s.substr(a, b - a);
}

}  // namespace

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

}  // namespace mitsuba_xml
}  // namespace voxcone

/// \file ply_loader.cpp
/// Stanford PLY reader (ascii, binary_little_endian, binary_big_endian). The whole file is read
/// into memory; the header is parsed line by line, the body with std::from_chars (ascii) or
/// memcpy plus byte swapping (binary). Every read is bounds-checked and every size claimed by
/// the header is checked against the bytes that are left before anything is allocated.

#include "voxcone/core/error.h"
#include "voxcone/scene/mesh.h"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <utility>
#include <memory>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

namespace voxcone {
namespace {

/// Scalar types a PLY property can have.
enum class PlyType { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64, Invalid };

enum class PlyFormat { Ascii, BinaryLittle, BinaryBig };

/// Size in bytes of a scalar type in the binary formats.
size_t typeSize(PlyType t) {
  switch (t) {
    case PlyType::Int8:
    case PlyType::UInt8: return 1;
    case PlyType::Int16:
    case PlyType::UInt16: return 2;
    case PlyType::Int32:
    case PlyType::UInt32:
    case PlyType::Float32: return 4;
    case PlyType::Float64: return 8;
    default: return 0;
  }
}

bool isIntegerType(PlyType t) { return t != PlyType::Float32 && t != PlyType::Float64; }

PlyType parseType(std::string_view s) {
  if (s == "char" || s == "int8") return PlyType::Int8;
  if (s == "uchar" || s == "uint8") return PlyType::UInt8;
  if (s == "short" || s == "int16") return PlyType::Int16;
  if (s == "ushort" || s == "uint16") return PlyType::UInt16;
  if (s == "int" || s == "int32") return PlyType::Int32;
  if (s == "uint" || s == "uint32") return PlyType::UInt32;
  if (s == "float" || s == "float32") return PlyType::Float32;
  if (s == "double" || s == "float64") return PlyType::Float64;
  return PlyType::Invalid;
}

/// One `property` line of the header.
struct PlyProperty {
  std::string name;
  bool isList = false;
  PlyType countType = PlyType::Invalid; ///< list count type (lists only)
  PlyType valueType = PlyType::Invalid; ///< scalar type, or list item type
};

/// One `element` line of the header with its properties.
struct PlyElement {
  std::string name;
  uint64_t count = 0;
  size_t headerLine = 0;
  std::vector<PlyProperty> properties;

  /// Smallest number of bytes one row can take in a binary file (lists count as empty).
  size_t minBinaryRowSize() const {
    size_t s = 0;
    for (const PlyProperty& p : properties) s += typeSize(p.isList ? p.countType : p.valueType);
    return s;
  }
  /// True when every property is a scalar, so rows have a fixed size in binary files.
  bool fixedSize() const {
    for (const PlyProperty& p : properties)
      if (p.isList) return false;
    return true;
  }
  int find(std::string_view n) const {
    for (size_t i = 0; i < properties.size(); ++i)
      if (properties[i].name == n) return int(i);
    return -1;
  }
};

/// Plural used in "expected N vertices" messages.
std::string plural(const std::string& element) {
  if (element == "vertex") return "vertices";
  return element + "s";
}

/// Role a property plays for the loader: one of the eight vertex slots (position, normal,
/// texture coordinates), the face index list, or nothing (skipped).
enum Role : int { kX = 0, kY, kZ, kNx, kNy, kNz, kU, kV, kFaceIndices, kSkip };

/// Reads one PLY file. Holds the bytes and the parse state; throws MeshError on any problem.
class PlyReader {
public:
  explicit PlyReader(std::string path) : m_path(std::move(path)) {}

  TriangleMesh read() {
    readFile();
    return parse();
  }
  /// `bytes` as the file's content (named m_path in errors).
  TriangleMesh read(std::string bytes) {
    m_data = std::move(bytes);
    return parse();
  }

private:
  TriangleMesh parse() {
    parseHeader();
    setUpRoles();
    for (const PlyElement& e : m_elements) {
      if (m_format == PlyFormat::Ascii)
        readElementAscii(e);
      else
        readElementBinary(e);
    }
    if (!m_hasNormals) m_mesh.normals.clear();
    return std::move(m_mesh);
  }

  [[noreturn]] void fail(const std::string& what) const { throw MeshError(m_path, what); }

  //--------------------------------------------------------------------------------------------
  // File and header

  void readFile() {
    std::error_code ec;
    if (!std::filesystem::exists(m_path, ec)) fail("cannot open file: no such file");
    if (std::filesystem::is_directory(m_path, ec)) fail("cannot open file: is a directory");
    std::unique_ptr<FILE, int (*)(FILE*)> f(std::fopen(m_path.c_str(), "rb"), &std::fclose);
    if (!f) fail(std::string("cannot open file: ") + std::strerror(errno));
    // Read the size the file system reports, then on until EOF (for files whose size is not
    // known in advance, or that grew).
    std::string data;
    const uintmax_t size = std::filesystem::file_size(m_path, ec);
    size_t have = 0;
    if (!ec && size > 0) {
      data.resize(size_t(size));
      have = std::fread(data.data(), 1, data.size(), f.get());
      data.resize(have);
    }
    char chunk[1 << 16];
    size_t n;
    while ((n = std::fread(chunk, 1, sizeof(chunk), f.get())) > 0) data.append(chunk, n);
    if (std::ferror(f.get())) fail("read error");
    m_data = std::move(data);
  }

  /// Splits a header line into whitespace-separated tokens.
  static std::vector<std::string_view> tokenize(std::string_view line) {
    std::vector<std::string_view> out;
    size_t i = 0;
    while (i < line.size()) {
      while (i < line.size() && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r')) ++i;
      size_t j = i;
      while (j < line.size() && line[j] != ' ' && line[j] != '\t' && line[j] != '\r') ++j;
      if (j > i) out.push_back(line.substr(i, j - i));
      i = j;
    }
    return out;
  }

  static std::string clip(std::string_view s) {
    std::string r;
    for (char c : s.substr(0, 24)) r += (c >= 32 && c < 127) ? c : '?';
    if (s.size() > 24) r += "...";
    return r;
  }

  void parseHeader() {
    const std::string_view all(m_data);
    if (all.size() < 4 || all.compare(0, 3, "ply") != 0 || (all[3] != '\n' && all[3] != '\r'))
      fail("not a PLY file (missing 'ply' magic line)");

    bool haveFormat = false;
    size_t pos = 0;
    size_t line = 0;
    while (true) {
      if (pos >= all.size()) fail("header: missing end_header");
      size_t eol = all.find('\n', pos);
      const bool lastLine = eol == std::string_view::npos;
      if (lastLine) eol = all.size();
      const std::string_view text = all.substr(pos, eol - pos);
      pos = lastLine ? all.size() : eol + 1;
      ++line;
      if (line == 1) continue;  // the magic line
      const std::string where = "line " + std::to_string(line) + ": ";

      const std::vector<std::string_view> tok = tokenize(text);
      if (tok.empty()) continue;
      const std::string_view key = tok[0];
      if (key == "comment" || key == "obj_info") continue;
      if (key == "end_header") {
        if (!haveFormat) fail(where + "end_header before any format line");
        m_bodyStart = pos;
        m_bodyLine = line + 1;
        break;
      }
      if (key == "format") {
        if (tok.size() < 2) fail(where + "format line without a format");
        if (tok[1] == "ascii")
          m_format = PlyFormat::Ascii;
        else if (tok[1] == "binary_little_endian")
          m_format = PlyFormat::BinaryLittle;
        else if (tok[1] == "binary_big_endian")
          m_format = PlyFormat::BinaryBig;
        else
          fail(where + "unknown format '" + clip(tok[1]) + "'");
        haveFormat = true;
        continue;
      }
      if (key == "element") {
        if (tok.size() != 3) fail(where + "expected 'element <name> <count>'");
        PlyElement e;
        e.name = std::string(tok[1]);
        e.headerLine = line;
        int64_t count = 0;
        const auto [ptr, ec] = std::from_chars(tok[2].data(), tok[2].data() + tok[2].size(), count);
        if (ec != std::errc() || ptr != tok[2].data() + tok[2].size())
          fail(where + "bad element count '" + clip(tok[2]) + "'");
        if (count < 0) fail(where + "negative count for element '" + e.name + "'");
        e.count = uint64_t(count);
        for (const PlyElement& other : m_elements)
          if (other.name == e.name) fail(where + "duplicate element '" + e.name + "'");
        m_elements.push_back(std::move(e));
        continue;
      }
      if (key == "property") {
        if (m_elements.empty()) fail(where + "property before any element");
        PlyProperty p;
        if (tok.size() >= 2 && tok[1] == "list") {
          if (tok.size() != 5) fail(where + "expected 'property list <count type> <type> <name>'");
          p.isList = true;
          p.countType = parseType(tok[2]);
          p.valueType = parseType(tok[3]);
          p.name = std::string(tok[4]);
          if (p.countType == PlyType::Invalid) fail(where + "unknown type '" + clip(tok[2]) + "'");
          if (p.valueType == PlyType::Invalid) fail(where + "unknown type '" + clip(tok[3]) + "'");
          if (!isIntegerType(p.countType))
            fail(where + "list count type must be an integer type, not '" + clip(tok[2]) + "'");
        } else {
          if (tok.size() != 3) fail(where + "expected 'property <type> <name>'");
          p.valueType = parseType(tok[1]);
          p.name = std::string(tok[2]);
          if (p.valueType == PlyType::Invalid) fail(where + "unknown type '" + clip(tok[1]) + "'");
        }
        m_elements.back().properties.push_back(std::move(p));
        continue;
      }
      fail(where + "unknown header keyword '" + clip(key) + "'");
    }

#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
    m_swap = m_format == PlyFormat::BinaryLittle;
#else
    m_swap = m_format == PlyFormat::BinaryBig;
#endif
  }

  /// Finds the vertex and face properties the mesh needs and checks their types.
  void setUpRoles() {
    const PlyElement* vertex = nullptr;
    for (const PlyElement& e : m_elements) {
      std::vector<Role> roles(e.properties.size(), kSkip);
      const std::string where = "line " + std::to_string(e.headerLine) + ": ";
      if (e.name == "vertex") {
        vertex = &e;
        static const char* kNames[6] = {"x", "y", "z", "nx", "ny", "nz"};
        int idx[6];
        for (int k = 0; k < 6; ++k) {
          idx[k] = e.find(kNames[k]);
          if (idx[k] >= 0 && e.properties[idx[k]].isList)
            fail(where + "vertex property '" + kNames[k] + "' is a list");
        }
        for (int k = 0; k < 3; ++k)
          if (idx[k] < 0) fail(where + "vertex element has no '" + kNames[k] + "' property");
        m_hasNormals = idx[3] >= 0 && idx[4] >= 0 && idx[5] >= 0;
        for (int k = 0; k < (m_hasNormals ? 6 : 3); ++k) roles[idx[k]] = Role(k);
        // Texture coordinates: u v (Blender, Mitsuba), s t, or texture_u texture_v.
        for (const auto& [un, vn] : {std::pair{"u", "v"}, {"s", "t"}, {"texture_u", "texture_v"}}) {
          const int iu = e.find(un), iv = e.find(vn);
          if (iu < 0 || iv < 0) continue;
          if (e.properties[iu].isList || e.properties[iv].isList)
            fail(where + "vertex property '" + un + "' or '" + vn + "' is a list");
          roles[iu] = kU;
          roles[iv] = kV;
          m_hasUvs = true;
          break;
        }
        if (e.count > std::numeric_limits<uint32_t>::max())
          fail(where + "too many vertices (" + std::to_string(e.count) + ")");
        m_vertexCount = e.count;
      } else if (e.name == "face") {
        int i = e.find("vertex_indices");
        if (i < 0) i = e.find("vertex_index");
        if (i < 0) fail(where + "face element has no 'vertex_indices' list");
        const PlyProperty& p = e.properties[i];
        if (!p.isList) fail(where + "face property '" + p.name + "' is not a list");
        if (!isIntegerType(p.valueType)) fail(where + "face indices must have an integer type");
        roles[i] = kFaceIndices;
      }
      m_roles.push_back(std::move(roles));
    }
    if (!vertex) fail("header: no 'vertex' element");
  }

  //--------------------------------------------------------------------------------------------
  // Face assembly shared by both formats

  /// Checks one face corner index. `face` is the face number (0-based) for the message.
  uint32_t checkIndex(int64_t v, uint64_t face) const {
    if (v < 0 || uint64_t(v) >= m_vertexCount)
      fail((m_format == PlyFormat::Ascii ? lineWhere() : std::string()) + "face " +
           std::to_string(face) + ": vertex index " + std::to_string(v) + " out of range (" +
           std::to_string(m_vertexCount) + " vertices)");
    return uint32_t(v);
  }

  //--------------------------------------------------------------------------------------------
  // ASCII body

  /// Skips whitespace, counting lines. Returns false at the end of the data.
  bool skipSpace() {
    const char* p = m_cur;
    const char* end = m_end;
    while (p < end) {
      const char c = *p;
      if (c == '\n')
        ++m_line;
      else if (c != ' ' && c != '\t' && c != '\r' && c != '\f' && c != '\v')
        break;
      ++p;
    }
    m_cur = p;
    return p < end;
  }

  static bool isSpace(char c) {
    return c == ' ' || c == '\n' || c == '\t' || c == '\r' || c == '\f' || c == '\v';
  }

  [[noreturn]] void truncated(const PlyElement& e, uint64_t row) const {
    fail("truncated: expected " + std::to_string(e.count) + " " + plural(e.name) + ", got " +
         std::to_string(row));
  }

  [[noreturn]] void badValue(const PlyElement& e, const char* tokenStart) const {
    const char* t = tokenStart;
    while (t < m_end && !isSpace(*t)) ++t;
    fail("line " + std::to_string(m_line) + ": bad " + e.name + " value '" +
         clip(std::string_view(tokenStart, size_t(t - tokenStart))) + "'");
  }

  /// Parses one ascii number as float (correctly rounded from the text, whatever its type).
  float asciiFloat(const PlyElement& e, uint64_t row) {
    if (!skipSpace()) truncated(e, row);
    const char* start = m_cur;
    const char* p = start;
    if (*p == '+') ++p;
    float v = 0.0f;
    auto [ptr, ec] = std::from_chars(p, m_end, v);
    if (ec == std::errc::result_out_of_range) {
      // Underflow is harmless (the value rounds to zero or a denormal); overflow is an error.
      double d = 0.0;
      auto r = std::from_chars(p, m_end, d);
      if (r.ec != std::errc() || std::fabs(d) > double(std::numeric_limits<float>::max()))
        badValue(e, start);
      v = float(d);
      ptr = r.ptr;
      ec = std::errc();
    }
    if (ec != std::errc() || (ptr < m_end && !isSpace(*ptr))) badValue(e, start);
    m_cur = ptr;
    return v;
  }

  /// Parses one ascii integer (list counts and indices).
  int64_t asciiInt(const PlyElement& e, uint64_t row) {
    if (!skipSpace()) truncated(e, row);
    const char* start = m_cur;
    const char* p = start;
    bool negative = false;
    if (*p == '+' || *p == '-') negative = *p++ == '-';
    // Hand-rolled: faster than std::from_chars for the short integers of face lists. At most
    // 18 digits, so the value cannot overflow.
    int64_t v = 0;
    const char* digits = p;
    while (p < m_end && unsigned(*p - '0') < 10u && p - digits < 18) v = v * 10 + (*p++ - '0');
    if (p == digits || (p < m_end && !isSpace(*p))) badValue(e, start);
    m_cur = p;
    return negative ? -v : v;
  }

  /// Skips one ascii token.
  void asciiSkip(const PlyElement& e, uint64_t row) {
    if (!skipSpace()) truncated(e, row);
    const char* p = m_cur;
    while (p < m_end && !isSpace(*p)) ++p;
    m_cur = p;
  }

  std::string lineWhere() const { return "line " + std::to_string(m_line) + ": "; }

  void readElementAscii(const PlyElement& e) {
    if (m_cur == nullptr) {
      m_cur = m_data.data() + m_bodyStart;
      m_end = m_data.data() + m_data.size();
      m_line = m_bodyLine;
    }
    if (e.properties.empty()) return;  // rows without properties hold no data
    const std::vector<Role>& roles = m_roles[&e - m_elements.data()];
    const bool isVertex = e.name == "vertex";
    const bool isFace = e.name == "face";

    // Each value takes at least one character and one separator (a triangle's list four
    // values): cap the reservation by what the file can hold, so that an absurd count cannot
    // allocate absurd memory.
    const uint64_t minValues = e.properties.size() + (isFace ? 3 : 0);
    const uint64_t cap = uint64_t(m_end - m_cur) / (2 * minValues) + 1;
    const size_t reserve = size_t(std::min(e.count, cap));
    if (isVertex) {
      m_mesh.positions.reserve(reserve);
      if (m_hasNormals) m_mesh.normals.reserve(reserve);
      if (m_hasUvs) m_mesh.uvs.reserve(reserve);
    } else if (isFace) {
      m_mesh.triangles.reserve(reserve);
    }

    float slot[8] = {0, 0, 0, 0, 0, 0, 0, 0};
    for (uint64_t row = 0; row < e.count; ++row) {
      for (size_t k = 0; k < e.properties.size(); ++k) {
        const PlyProperty& p = e.properties[k];
        const Role role = roles[k];
        if (role <= kV) {
          slot[role] = asciiFloat(e, row);
        } else if (role == kFaceIndices) {
          const int64_t n = asciiInt(e, row);
          if (n < 0) fail(lineWhere() + "negative vertex count in face " + std::to_string(row));
          // Fan triangulation: (v0, v[i-1], v[i]) for i >= 2.
          uint32_t v0 = 0, prev = 0;
          for (int64_t i = 0; i < n; ++i) {
            const uint32_t v = checkIndex(asciiInt(e, row), row);
            if (i == 0)
              v0 = v;
            else if (i >= 2)
              m_mesh.triangles.emplace_back(v0, prev, v);
            prev = v;
          }
        } else if (p.isList) {
          const int64_t n = asciiInt(e, row);
          if (n < 0)
            fail(lineWhere() + "negative count in list '" + p.name + "' of " + e.name + " " +
                 std::to_string(row));
          for (int64_t i = 0; i < n; ++i) asciiSkip(e, row);
        } else {
          asciiSkip(e, row);
        }
      }
      if (isVertex) addVertex(slot, row);
    }
  }

  void addVertex(const float* slot, uint64_t row) {
    const Vec3 pos(slot[0], slot[1], slot[2]);
    if (!isFinite(pos))
      fail((m_format == PlyFormat::Ascii ? lineWhere() : std::string()) + "vertex " +
           std::to_string(row) + ": non-finite coordinate");
    m_mesh.positions.push_back(pos);
    if (m_hasNormals) m_mesh.normals.emplace_back(slot[3], slot[4], slot[5]);
    if (m_hasUvs) {
      const Vec2 uv(slot[kU], slot[kV]);
      if (!std::isfinite(uv.x) || !std::isfinite(uv.y))
        fail((m_format == PlyFormat::Ascii ? lineWhere() : std::string()) + "vertex " + std::to_string(row) +
             ": non-finite texture coordinate");
      m_mesh.uvs.push_back(uv);
    }
  }

  //--------------------------------------------------------------------------------------------
  // Binary body

  template <typename T> T load(const char* p) const {
    T v;
    std::memcpy(&v, p, sizeof(T));
    if (m_swap) {
      char b[sizeof(T)];
      std::memcpy(b, &v, sizeof(T));
      for (size_t i = 0; i < sizeof(T) / 2; ++i) std::swap(b[i], b[sizeof(T) - 1 - i]);
      std::memcpy(&v, b, sizeof(T));
    }
    return v;
  }

  double loadFloat(const char* p, PlyType t) const {
    switch (t) {
      case PlyType::Int8: return double(load<int8_t>(p));
      case PlyType::UInt8: return double(load<uint8_t>(p));
      case PlyType::Int16: return double(load<int16_t>(p));
      case PlyType::UInt16: return double(load<uint16_t>(p));
      case PlyType::Int32: return double(load<int32_t>(p));
      case PlyType::UInt32: return double(load<uint32_t>(p));
      case PlyType::Float32: return double(load<float>(p));
      case PlyType::Float64: return load<double>(p);
      default: return 0.0;
    }
  }

  /// Loads an integer-typed value (validated in the header) as a signed 64-bit number.
  int64_t loadInt(const char* p, PlyType t) const {
    switch (t) {
      case PlyType::Int8: return load<int8_t>(p);
      case PlyType::UInt8: return load<uint8_t>(p);
      case PlyType::Int16: return load<int16_t>(p);
      case PlyType::UInt16: return load<uint16_t>(p);
      case PlyType::Int32: return load<int32_t>(p);
      case PlyType::UInt32: return load<uint32_t>(p);
      default: return -1;
    }
  }

  void readElementBinary(const PlyElement& e) {
    if (m_cur == nullptr) {
      m_cur = m_data.data() + m_bodyStart;
      m_end = m_data.data() + m_data.size();
    }
    if (e.properties.empty()) return;
    const std::vector<Role>& roles = m_roles[&e - m_elements.data()];
    const bool isVertex = e.name == "vertex";
    const bool isFace = e.name == "face";

    // Every row takes at least minRow bytes: check the count against what is left before
    // allocating or looping.
    const size_t minRow = e.minBinaryRowSize();
    const uint64_t left = uint64_t(m_end - m_cur);
    if (e.count > left / minRow) truncated(e, left / minRow);

    // Fixed-size rows of an element the mesh does not use: skip them in one step.
    if (!isVertex && !isFace && e.fixedSize()) {
      m_cur += e.count * minRow;
      return;
    }
    if (isVertex) {
      m_mesh.positions.reserve(size_t(e.count));
      if (m_hasNormals) m_mesh.normals.reserve(size_t(e.count));
      if (m_hasUvs) m_mesh.uvs.reserve(size_t(e.count));
    } else if (isFace) {
      // Reserve one triangle per face, as many as the bytes left can hold.
      size_t triangleRow = minRow;
      for (size_t k = 0; k < e.properties.size(); ++k)
        if (roles[k] == kFaceIndices) triangleRow += 3 * typeSize(e.properties[k].valueType);
      m_mesh.triangles.reserve(size_t(std::min<uint64_t>(e.count, left / triangleRow)));
    }

    const char* p = m_cur;
    const char* end = m_end;
    float slot[8] = {0, 0, 0, 0, 0, 0, 0, 0};
    for (uint64_t row = 0; row < e.count; ++row) {
      for (size_t k = 0; k < e.properties.size(); ++k) {
        const PlyProperty& prop = e.properties[k];
        const Role role = roles[k];
        if (!prop.isList) {
          const size_t sz = typeSize(prop.valueType);
          if (size_t(end - p) < sz) truncated(e, row);
          if (role <= kV) slot[role] = float(loadFloat(p, prop.valueType));
          p += sz;
          continue;
        }
        const size_t csz = typeSize(prop.countType);
        if (size_t(end - p) < csz) truncated(e, row);
        const int64_t n = loadInt(p, prop.countType);
        p += csz;
        if (n < 0)
          fail(e.name + " " + std::to_string(row) + ": negative count in list '" + prop.name + "'");
        const size_t isz = typeSize(prop.valueType);
        if (uint64_t(n) > uint64_t(end - p) / isz) truncated(e, row);
        if (role == kFaceIndices) {
          // Fan triangulation: (v0, v[i-1], v[i]) for i >= 2.
          uint32_t v0 = 0, prev = 0;
          for (int64_t i = 0; i < n; ++i) {
            const uint32_t v = checkIndex(loadInt(p, prop.valueType), row);
            p += isz;
            if (i == 0)
              v0 = v;
            else if (i >= 2)
              m_mesh.triangles.emplace_back(v0, prev, v);
            prev = v;
          }
        } else {
          p += size_t(n) * isz;
        }
      }
      if (isVertex) addVertex(slot, row);
    }
    m_cur = p;
  }

  std::string m_path;
  std::string m_data;
  PlyFormat m_format = PlyFormat::Ascii;
  bool m_swap = false;
  size_t m_bodyStart = 0;
  size_t m_bodyLine = 0;
  std::vector<PlyElement> m_elements;
  std::vector<std::vector<Role>> m_roles;  ///< per element, per property
  bool m_hasNormals = false;
  bool m_hasUvs = false;
  uint64_t m_vertexCount = 0;

  const char* m_cur = nullptr;  ///< body cursor
  const char* m_end = nullptr;
  size_t m_line = 0;  ///< current line (ascii body)

  TriangleMesh m_mesh;
};

}  // namespace

TriangleMesh loadPly(const std::string& path) { return PlyReader(path).read(); }
TriangleMesh parsePly(std::string bytes, const std::string& name) { return PlyReader(name).read(std::move(bytes)); }

}  // namespace voxcone

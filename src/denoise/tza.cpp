#include "voxcone/denoise/tza.h"

#include "voxcone/core/error.h"

#include <cstring>
#include <fstream>
#include <iterator>

namespace voxcone {

size_t TzaTensor::size() const {
  size_t n = 1;
  for (int d : dims) n *= size_t(d);
  return n;
}

float halfToFloat(uint16_t h) {
  const uint32_t sign = uint32_t(h >> 15) << 31;
  const uint32_t exponent = (h >> 10) & 0x1fu;
  uint32_t mantissa = h & 0x3ffu;
  uint32_t bits;
  if (exponent == 0x1f) {
    bits = sign | 0x7f800000u | (mantissa << 13);  // infinity or NaN
  } else if (exponent != 0) {
    bits = sign | ((exponent + 112u) << 23) | (mantissa << 13);  // rebias 15 -> 127
  } else if (mantissa == 0) {
    bits = sign;  // signed zero
  } else {
    // Subnormal: normalize the mantissa.
    int e = -1;
    do {
      ++e;
      mantissa <<= 1;
    } while ((mantissa & 0x400u) == 0);
    bits = sign | (uint32_t(112 - e) << 23) | ((mantissa & 0x3ffu) << 13);
  }
  float f;
  std::memcpy(&f, &bits, sizeof f);
  return f;
}

namespace {

/// Little-endian reads with bounds checks against the archive's end.
class Reader {
public:
  Reader(const std::vector<uint8_t>& bytes, const std::string& what) : m_bytes(bytes), m_what(what) {}
  void seek(uint64_t at) {
    if (at > m_bytes.size()) fail("offset " + std::to_string(at) + " past the end");
    m_at = size_t(at);
  }
  template <class T>
  T read() {
    need(sizeof(T));
    T v = 0;
    for (size_t i = 0; i < sizeof(T); ++i) v = T(v | (T(m_bytes[m_at + i]) << (8 * i)));
    m_at += sizeof(T);
    return v;
  }
  std::string text(size_t n) {
    need(n);
    std::string s(reinterpret_cast<const char*>(m_bytes.data() + m_at), n);
    m_at += n;
    return s;
  }
  [[noreturn]] void fail(const std::string& why) const { throw ImageError(m_what + ": not a valid .tza: " + why); }

private:
  void need(size_t n) const {
    if (n > m_bytes.size() - m_at) fail("truncated");
  }
  const std::vector<uint8_t>& m_bytes;
  const std::string& m_what;
  size_t m_at = 0;
};

}  // namespace

std::map<std::string, TzaTensor> parseTza(const std::vector<uint8_t>& bytes, const std::string& what) {
  Reader r(bytes, what);
  if (r.read<uint16_t>() != 0x41D7) r.fail("bad magic");
  const int major = r.read<uint8_t>();
  r.read<uint8_t>();  // minor version
  if (major != 2) r.fail("version " + std::to_string(major) + " (only 2 is read)");
  // The tensors' data lies between the header and the table (as OIDN's writer places it).
  const uint64_t table = r.read<uint64_t>();
  r.seek(table);
  const uint32_t count = r.read<uint32_t>();
  std::map<std::string, TzaTensor> out;
  for (uint32_t i = 0; i < count; ++i) {
    const std::string name = r.text(r.read<uint16_t>());
    TzaTensor t;
    const int ndims = r.read<uint8_t>();
    if (ndims == 0) r.fail("tensor '" + name + "' has no dimensions");
    for (int d = 0; d < ndims; ++d) {
      const uint32_t dim = r.read<uint32_t>();
      if (dim == 0 || dim > (1u << 20)) r.fail("tensor '" + name + "' has a dimension of " + std::to_string(dim));
      t.dims.push_back(int(dim));
    }
    t.layout = r.text(size_t(ndims));
    if (t.layout != "x" && t.layout != "oihw") r.fail("tensor '" + name + "' has layout '" + t.layout + "'");
    const char type = char(r.read<uint8_t>());
    if (type != 'f' && type != 'h') r.fail("tensor '" + name + "' has data type '" + std::string(1, type) + "'");
    const uint64_t offset = r.read<uint64_t>();
    const size_t n = t.size();
    const size_t elementBytes = type == 'f' ? 4 : 2;
    if (offset < 12 || offset > table || n > (table - offset) / elementBytes)
      r.fail("tensor '" + name + "' lies past the end of the data");
    t.values.resize(n);
    const uint8_t* p = bytes.data() + offset;
    for (size_t k = 0; k < n; ++k) {
      if (type == 'h') {
        t.values[k] = halfToFloat(uint16_t(p[2 * k] | (p[2 * k + 1] << 8)));
      } else {
        uint32_t bits = 0;
        for (int b = 0; b < 4; ++b) bits |= uint32_t(p[4 * k + size_t(b)]) << (8 * b);
        std::memcpy(&t.values[k], &bits, 4);
      }
    }
    if (!out.emplace(name, std::move(t)).second) r.fail("tensor '" + name + "' is given twice");
  }
  return out;
}

std::map<std::string, TzaTensor> readTza(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ImageError(path + ": cannot open the denoiser's weights");
  const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw ImageError(path + ": cannot read the denoiser's weights");
  return parseTza(bytes, path);
}

}  // namespace voxcone

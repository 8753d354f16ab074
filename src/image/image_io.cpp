/// \file image_io.cpp
/// Image files through OpenImageIO (the only file besides metrics.cpp that includes it), and the
/// atomic write used for every output file.

#include "voxcone/image/image_io.h"

#include "voxcone/core/error.h"

#include <OpenImageIO/imageio.h>
#include <nlohmann/json.hpp>

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <charconv>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <mutex>
#include <string>
#include <vector>

namespace voxcone {

namespace {

namespace fs = std::filesystem;

/// Largest JSON dump stored whole in the "voxcone:metadata" EXR attribute. OpenEXR headers have
/// no hard limit, but readers (and OpenEXR's own sanity checks) dislike huge headers; the
/// per-key attributes carry the same content anyway.
constexpr size_t kMaxExrMetadataBytes = 64 * 1024;

/// First line of an OpenImageIO error text (its messages can span several lines).
std::string firstLine(const std::string& text) {
  const size_t end = text.find_first_of("\r\n");
  std::string line = text.substr(0, end);
  return line.empty() ? std::string("unknown OpenImageIO error") : line;
}

/// Counter making temporary names unique within one process (several threads may write).
std::atomic<unsigned> g_tmpCounter{0};

/// Remove temporaries of `target` (".<stem>.tmp-<pid>-<n><ext>") left by a process that no
/// longer exists (killed with SIGKILL mid-write: nothing else would ever remove them).
void removeStaleTemporaries(const fs::path& dir, const fs::path& target) {
  const std::string prefix = "." + target.stem().string() + ".tmp-", ext = target.extension().string();
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.size() <= prefix.size() + ext.size() || name.compare(0, prefix.size(), prefix) != 0 ||
        name.compare(name.size() - ext.size(), ext.size(), ext) != 0)
      continue;
    const std::string rest = name.substr(prefix.size());  // "<pid>-<n><ext>"
    long pid = 0;
    const auto [ptr, perr] = std::from_chars(rest.data(), rest.data() + rest.size(), pid);
    if (perr != std::errc() || ptr == rest.data() || *ptr != '-' || pid <= 0) continue;
    if (pid == long(::getpid())) continue;
    if (::kill(pid_t(pid), 0) == 0 || errno != ESRCH) continue;  // alive, or not ours to judge
    std::error_code rm;
    fs::remove(it->path(), rm);
  }
}

/// The temporary `path` is written to: ".<stem>.tmp-<pid>-<counter><ext>" in its folder,
/// hidden, unique, and with the target's extension so that OpenImageIO picks the same format
/// for the temporary as for the target. Stale temporaries of the target go first.
template <typename ErrorT>
std::string temporaryFor(const std::string& path) {
  const fs::path target(path);
  if (target.filename().empty()) throw ErrorT(path + ": not a file path");
  const fs::path dir = target.parent_path().empty() ? fs::path(".") : target.parent_path();
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw ErrorT(path + ": directory " + dir.string() + " does not exist");
  removeStaleTemporaries(dir, target);
  const std::string tmpName = "." + target.stem().string() + ".tmp-" + std::to_string(::getpid()) + "-" +
                              std::to_string(g_tmpCounter.fetch_add(1)) + target.extension().string();
  return (dir / tmpName).string();
}

/// writeFileAtomic throwing ErrorT, so that image writes report ImageError as documented; with
/// `set`, the temporary joins the set instead of being renamed now.
template <typename ErrorT>
void atomicWrite(const std::string& path, const std::function<void(const std::string&)>& writer,
                 OutputSet* set = nullptr) {
  if (set) {
    set->add(path, writer);
    return;
  }
  const std::string tmpPath = temporaryFor<ErrorT>(path);
  std::error_code ec;
  try {
    writer(tmpPath);
    if (std::rename(tmpPath.c_str(), path.c_str()) != 0)
      throw ErrorT(path + ": cannot rename temporary file " + tmpPath + ": " + std::strerror(errno));
  } catch (...) {
    fs::remove(tmpPath, ec);
    throw;
  }
}

/// Write `pixels` (width*height*3 values of `format`) to `tmpPath` with OpenImageIO.
void writeWithOiio(const std::string& path, const std::string& tmpPath, const OIIO::ImageSpec& spec,
                   const void* pixels) {
  auto out = OIIO::ImageOutput::create(tmpPath);
  if (!out) throw ImageError(path + ": cannot create image writer: " + firstLine(OIIO::geterror()));
  if (!out->open(tmpPath, spec)) throw ImageError(path + ": cannot open for writing: " + firstLine(out->geterror()));
  if (!out->write_image(spec.format, pixels)) {
    const std::string msg = firstLine(out->geterror());
    out->close();
    throw ImageError(path + ": cannot write image: " + msg);
  }
  if (!out->close()) throw ImageError(path + ": cannot finish writing: " + firstLine(out->geterror()));
}

void checkImage(const std::string& path, const Image& image) {
  if (image.width <= 0 || image.height <= 0 ||
      image.pixels.size() != static_cast<size_t>(image.width) * static_cast<size_t>(image.height))
    throw ImageError(path + ": cannot write an empty or inconsistent image (" + std::to_string(image.width) + "x" +
                     std::to_string(image.height) + ", " + std::to_string(image.pixels.size()) + " pixels)");
}

/// Lower-case extension of `path` including the dot ("" if none).
std::string lowerExtension(const std::string& path) {
  std::string ext = fs::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

bool startsWithNoCase(const std::string& s, const char* prefix) {
  const size_t n = std::strlen(prefix);
  if (s.size() < n) return false;
  for (size_t i = 0; i < n; ++i)
    if (std::tolower(static_cast<unsigned char>(s[i])) != std::tolower(static_cast<unsigned char>(prefix[i])))
      return false;
  return true;
}

}  // namespace

float linearToSrgb(float linear) {
  // NaN fails both comparisons and becomes 0.
  const float v = linear > 0.0f ? (linear < 1.0f ? linear : 1.0f) : 0.0f;
  // IEC 61966-2-1 OETF: linear toe below 0.0031308, 2.4 power segment above.
  return v <= 0.0031308f ? 12.92f * v : 1.055f * std::pow(v, 1.0f / 2.4f) - 0.055f;
}

float srgbToLinear(float encoded) {
  // Input clamped to [0,1] like linearToSrgb, so the pair round-trips on that range.
  const float e = encoded > 0.0f ? (encoded < 1.0f ? encoded : 1.0f) : 0.0f;
  return e <= 0.04045f ? e / 12.92f : std::pow((e + 0.055f) / 1.055f, 2.4f);
}

int toSrgb8(float linear) { return static_cast<int>(std::lround(255.0f * linearToSrgb(linear))); }

void writeFileAtomic(const std::string& path, const std::function<void(const std::string& tmpPath)>& writer) {
  atomicWrite<Error>(path, writer);
}

OutputSet::~OutputSet() {
  if (m_committed) return;
  std::error_code ec;
  for (const Entry& e : m_entries) fs::remove(e.tmp, ec);
}

void OutputSet::add(const std::string& path, const std::function<void(const std::string& tmpPath)>& writer) {
  const std::string tmp = temporaryFor<Error>(path);
  try {
    writer(tmp);
  } catch (...) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw;
  }
  std::lock_guard<std::mutex> lock(m_mutex);
  m_entries.push_back({path, tmp});
}

void OutputSet::commit(const std::string& last) {
  std::lock_guard<std::mutex> lock(m_mutex);
  // `last` (the sidecar that marks a set complete) is renamed after every other file.
  std::stable_partition(m_entries.begin(), m_entries.end(), [&](const Entry& e) { return e.path != last; });
  for (size_t i = 0; i < m_entries.size(); ++i) {
    if (std::rename(m_entries[i].tmp.c_str(), m_entries[i].path.c_str()) == 0) continue;
    const std::string why = std::strerror(errno);
    // Not part of a set: the files renamed before this one go, and the temporaries after it.
    std::error_code ec;
    for (size_t k = 0; k < m_entries.size(); ++k) fs::remove(k < i ? m_entries[k].path : m_entries[k].tmp, ec);
    m_committed = true;
    throw Error(m_entries[i].path + ": cannot rename temporary file " + m_entries[i].tmp + ": " + why);
  }
  m_committed = true;
}

void writeJsonAtomic(const std::string& path, const nlohmann::json& value, OutputSet* set) {
  std::string text;
  try {
    text = value.dump(2) + "\n";
  } catch (const nlohmann::json::exception& e) {
    throw Error(path + ": cannot serialise JSON: " + e.what());
  }
  atomicWrite<Error>(
      path,
      [&](const std::string& tmpPath) {
        std::ofstream file(tmpPath, std::ios::binary | std::ios::trunc);
        if (!file) throw Error(path + ": cannot open temporary file " + tmpPath + ": " + std::strerror(errno));
        file << text;
        file.close();
        if (!file) throw Error(path + ": cannot write temporary file " + tmpPath);
      },
      set);
}

std::vector<MetadataAttribute> metadataAttributes(const nlohmann::json& metadata) {
  std::vector<MetadataAttribute> out;
  const std::function<void(const nlohmann::json&, const std::string&, int)> walk = [&](const nlohmann::json& v,
                                                                                     const std::string& name, int depth) {
    if (v.is_null()) return;
    if (v.is_object() && depth < 4) {
      for (const auto& item : v.items()) walk(item.value(), name + (depth ? "." : ":") + item.key(), depth + 1);
    } else if (v.is_structured()) {
      out.push_back({name, v.dump()});
    } else {
      out.push_back({name, v});
    }
  };
  if (metadata.is_object()) walk(metadata, "voxcone", 0);
  return out;
}

namespace {

/// An attribute as OpenEXR types it: strings, 32-bit ints (bools as 0/1), floats; an integer
/// outside int's range (a 64-bit seed) as its decimal text, which loses nothing.
void setTypedAttribute(OIIO::ImageSpec& spec, const MetadataAttribute& a) {
  const nlohmann::json& v = a.value;
  if (v.is_string()) spec.attribute(a.name, v.get<std::string>());
  else if (v.is_boolean()) spec.attribute(a.name, v.get<bool>() ? 1 : 0);
  else if (v.is_number_integer()) {
    const bool fits = v.is_number_unsigned() ? v.get<uint64_t>() <= uint64_t(INT32_MAX)
                                             : v.get<int64_t>() >= INT32_MIN && v.get<int64_t>() <= INT32_MAX;
    if (fits) spec.attribute(a.name, int(v.get<int64_t>()));
    else spec.attribute(a.name, v.dump());
  } else if (v.is_number()) spec.attribute(a.name, v.get<float>());
}

}  // namespace

void writeExr(const std::string& path, const Image& image, const nlohmann::json& metadata, OutputSet* set,
              const std::vector<ImageLayer>& layers) {
  checkImage(path, image);
  const size_t npix = image.pixels.size();
  std::vector<std::string> names = {"R", "G", "B"};
  for (const ImageLayer& l : layers) {
    if (l.channels.empty() || l.values.size() != npix * l.channels.size())
      throw ImageError(path + ": layer " + l.name + " has " + std::to_string(l.values.size()) + " values for " +
                       std::to_string(l.channels.size()) + " channels of " + std::to_string(npix) + " pixels");
    names.insert(names.end(), l.channels.begin(), l.channels.end());
  }
  OIIO::ImageSpec spec(image.width, image.height, int(names.size()), OIIO::TypeDesc::FLOAT);
  spec.channelnames = names;
  // Lossless RLE: a rendered float image barely compresses (zip: 730 KB instead of 795 KB
  // uncompressed at 256x256), and zip took 12.5 ms of a 0.17 s render there, RLE 5 ms (758 KB).
  spec.attribute("compression", "rle");
  spec.attribute("oiio:ColorSpace", "Linear");
  for (const MetadataAttribute& a : metadataAttributes(metadata)) setTypedAttribute(spec, a);
  if (!metadata.is_null()) {
    const std::string whole = metadata.dump();
    if (whole.size() <= kMaxExrMetadataBytes) spec.attribute("voxcone:metadata", whole);
  }
  static_assert(sizeof(Vec3) == 3 * sizeof(float), "Image pixels must be packed float RGB");
  // RGB alone is the image's own buffer; with layers, every pixel's channels interleaved.
  std::vector<float> interleaved;
  if (!layers.empty()) {
    interleaved.resize(npix * names.size());
    float* out = interleaved.data();
    for (size_t i = 0; i < npix; ++i) {
      for (int c = 0; c < 3; ++c) *out++ = image.pixels[i][c];
      for (const ImageLayer& l : layers)
        for (size_t c = 0; c < l.channels.size(); ++c) *out++ = l.values[i * l.channels.size() + c];
    }
  }
  const void* data = layers.empty() ? static_cast<const void*>(image.pixels.data()) : interleaved.data();
  atomicWrite<ImageError>(path, [&](const std::string& tmpPath) { writeWithOiio(path, tmpPath, spec, data); }, set);
}

void writePng(const std::string& path, const Image& image, OutputSet* set, const nlohmann::json& metadata) {
  checkImage(path, image);
  // Quantise with toSrgb8 ourselves so that the file holds exactly the codes metrics use.
  std::vector<uint8_t> codes(image.pixels.size() * 3);
  for (size_t i = 0; i < image.pixels.size(); ++i) {
    const Vec3& p = image.pixels[i];
    codes[3 * i + 0] = static_cast<uint8_t>(toSrgb8(p.x));
    codes[3 * i + 1] = static_cast<uint8_t>(toSrgb8(p.y));
    codes[3 * i + 2] = static_cast<uint8_t>(toSrgb8(p.z));
  }
  OIIO::ImageSpec spec(image.width, image.height, 3, OIIO::TypeDesc::UINT8);
  spec.attribute("oiio:ColorSpace", "sRGB");
  // zlib level 1: 6.5 ms instead of 18 ms at 256x256 (the default 6), 74 KB.
  spec.attribute("png:compressionLevel", 1);
  // OpenImageIO writes string attributes as tEXt chunks and drops others: every value as text.
  if (metadata.is_object()) {
    if (metadata.contains("voxcone_version") && metadata["voxcone_version"].is_string())
      spec.attribute("Software", "voxcone " + metadata["voxcone_version"].get<std::string>());
    for (const MetadataAttribute& a : metadataAttributes(metadata))
      spec.attribute(a.name, a.value.is_string() ? a.value.get<std::string>() : a.value.dump());
  }
  atomicWrite<ImageError>(
      path, [&](const std::string& tmpPath) { writeWithOiio(path, tmpPath, spec, codes.data()); }, set);
}

void writeImage(const std::string& path, const Image& image, const nlohmann::json& metadata) {
  const std::string ext = lowerExtension(path);
  if (ext == ".exr") {
    writeExr(path, image, metadata);
  } else if (ext == ".png") {
    writePng(path, image, nullptr, metadata);
  } else {
    throw ImageError(path + ": unsupported image extension '" + ext + "' (use .exr or .png)");
  }
}

Image readImage(const std::string& path) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) throw ImageError(path + ": no such image file");
  // Keep unassociated alpha (PNG) as stored: the alpha channel is dropped below, and the colour
  // must not be premultiplied by it on the way.
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);
  auto in = OIIO::ImageInput::open(path, &config);
  if (!in) throw ImageError(path + ": cannot read image: " + firstLine(OIIO::geterror()));
  const OIIO::ImageSpec& spec = in->spec();
  const int nch = spec.nchannels;
  if (spec.width <= 0 || spec.height <= 0 || nch <= 0)
    throw ImageError(path + ": image has no pixels (" + std::to_string(spec.width) + "x" +
                     std::to_string(spec.height) + "x" + std::to_string(nch) + ")");

  // Read every channel as float (integer formats come back normalised to [0,1]).
  const size_t npix = static_cast<size_t>(spec.width) * static_cast<size_t>(spec.height);
  std::vector<float> buf(npix * static_cast<size_t>(nch));
  if (!in->read_image(0, 0, 0, nch, OIIO::TypeDesc::FLOAT, buf.data()))
    throw ImageError(path + ": cannot read pixels: " + firstLine(in->geterror()));
  in->close();

  // Integer files are display-encoded unless they say they are linear: PNG and JPEG report
  // "sRGB" (or nothing), PNG with a gAMA chunk reports "GammaX.Y" and oiio:Gamma.
  const std::string colorSpace = spec.get_string_attribute("oiio:ColorSpace");
  const bool integer = spec.format.basetype == OIIO::TypeDesc::UINT8 ||
                       spec.format.basetype == OIIO::TypeDesc::UINT16 ||
                       spec.format.basetype == OIIO::TypeDesc::INT8 || spec.format.basetype == OIIO::TypeDesc::INT16;
  enum class Decode { None, Srgb, Gamma } decode = Decode::None;
  float gamma = 1.0f;
  if (integer) {
    if (colorSpace.empty() || startsWithNoCase(colorSpace, "srgb")) {
      decode = Decode::Srgb;
    } else if (startsWithNoCase(colorSpace, "gamma")) {
      gamma = spec.get_float_attribute("oiio:Gamma", 2.2f);
      decode = gamma > 0.0f ? Decode::Gamma : Decode::Srgb;
    }
  }
  auto toLinear = [&](float v) {
    switch (decode) {
      case Decode::Srgb: return srgbToLinear(v);
      case Decode::Gamma: return std::pow(std::max(v, 0.0f), gamma);
      default: return v;
    }
  };

  // One or two channels (grey, grey + alpha) are replicated to RGB; of more, the ones named R,
  // G and B (an EXR with AOV layers), else the first three.
  int rgb[3] = {0, 1, 2};
  if (nch > 3) {
    const auto& names = spec.channelnames;
    const auto find = [&](const char* n) { return int(std::find(names.begin(), names.end(), n) - names.begin()); };
    const int r = find("R"), g = find("G"), b = find("B");
    if (r < nch && g < nch && b < nch) rgb[0] = r, rgb[1] = g, rgb[2] = b;
  }
  Image image(spec.width, spec.height);
  image.displayEncoded = integer;
  for (size_t i = 0; i < npix; ++i) {
    const float* p = &buf[i * static_cast<size_t>(nch)];
    if (nch < 3) {
      const float g = toLinear(p[0]);
      image.pixels[i] = Vec3(g);
    } else {
      image.pixels[i] = Vec3(toLinear(p[rgb[0]]), toLinear(p[rgb[1]]), toLinear(p[rgb[2]]));
    }
  }
  return image;
}

}  // namespace voxcone

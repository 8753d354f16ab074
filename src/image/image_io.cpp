/// \file image_io.cpp
/// Image files, and the atomic write used for every output file. OpenEXR through its C++ library,
/// PNG through libpng and JPEG through libjpeg, directly: OpenImageIO, which the executable used
/// to link for this, pulls in ~260 shared libraries (ffmpeg, gdcm, opencv, ...) whose loading and
/// relocation took 0.35 s of every run's start. Reading keeps OpenImageIO 2.4's conventions where
/// they decide the pixels (the tests read the same files with both): EXR channels in its order,
/// integer codes scaled by the float 1/max, PNG colour from sRGB / gAMA chunks.

#include "voxcone/image/image_io.h"

#include "voxcone/core/error.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFloatAttribute.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfIntAttribute.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <png.h>
#include <zlib.h>
// jpeglib.h needs FILE and size_t declared first.
#include <cstdio>
#include <jpeglib.h>
#include <jerror.h>
#include <nlohmann/json.hpp>

#include <strings.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <csetjmp>
#include <cstdint>
#include <charconv>
#include <csignal>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
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

/// First line of a library's error text (OpenEXR's messages can span several lines).
std::string firstLine(const std::string& text) {
  const size_t end = text.find_first_of("\r\n");
  std::string line = text.substr(0, end);
  return line.empty() ? std::string("unknown error") : line;
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
/// hidden, unique, and with the target's extension. Stale temporaries of the target go first.
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

/// Add attribute `name` to `header`, replacing one of that name (OpenEXR refuses to overwrite an
/// attribute of another type). A name OpenEXR refuses (empty, too long) leaves it out.
template <typename A>
void putAttribute(Imf::Header& header, const std::string& name, const A& attribute) {
  try {
    if (header.find(name) != header.end()) header.erase(name);
    header.insert(name, attribute);
  } catch (const std::exception&) {
  }
}

/// An attribute as OpenEXR types it: strings, 32-bit ints (bools as 0/1), floats; an integer
/// outside int's range (a 64-bit seed) as its decimal text, which loses nothing.
void setTypedAttribute(Imf::Header& header, const MetadataAttribute& a) {
  const nlohmann::json& v = a.value;
  if (v.is_string()) putAttribute(header, a.name, Imf::StringAttribute(v.get<std::string>()));
  else if (v.is_boolean()) putAttribute(header, a.name, Imf::IntAttribute(v.get<bool>() ? 1 : 0));
  else if (v.is_number_integer()) {
    const bool fits = v.is_number_unsigned() ? v.get<uint64_t>() <= uint64_t(INT32_MAX)
                                             : v.get<int64_t>() >= INT32_MIN && v.get<int64_t>() <= INT32_MAX;
    if (fits) putAttribute(header, a.name, Imf::IntAttribute(int(v.get<int64_t>())));
    else putAttribute(header, a.name, Imf::StringAttribute(v.dump()));
  } else if (v.is_number()) putAttribute(header, a.name, Imf::FloatAttribute(v.get<float>()));
}

/// The local time as OpenEXR's capDate wants it ("YYYY:MM:DD hh:mm:ss"), as OpenImageIO wrote it.
std::string capDate() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  ::localtime_r(&now, &tm);
  char text[64];
  std::snprintf(text, sizeof(text), "%4d:%02d:%02d %02d:%02d:%02d", tm.tm_year + 1900, tm.tm_mon + 1, tm.tm_mday,
                tm.tm_hour, tm.tm_min, tm.tm_sec);
  return text;
}

// ---- libpng and libjpeg report errors by longjmp: each function that calls them and may
// ---- jump holds nothing with a destructor; the callers own every buffer.

/// libpng's error pointer: the message of the error that ended a read or write.
struct PngErrorState {
  char message[256] = "unknown libpng error";
};

void pngError(png_structp png, png_const_charp message) {
  auto* state = static_cast<PngErrorState*>(png_get_error_ptr(png));
  if (state) std::snprintf(state->message, sizeof(state->message), "%s", message ? message : "libpng error");
  png_longjmp(png, 1);
}

void pngWarning(png_structp, png_const_charp) {}

/// Everything of a PNG write after the file is open; false (the message in the error state) on
/// a libpng error. 8-bit RGB, zlib level 1, sRGB chunk (with gAMA and cHRM), text.
bool pngWriteCore(png_structp png, png_infop info, FILE* file, int width, int height, const uint8_t* codes,
                  png_text* text, int textCount) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_init_io(png, file);
  // zlib level 1: 6.5 ms instead of 18 ms at 256x256 (the default 6), 74 KB.
  png_set_compression_level(png, 1);
  png_set_compression_strategy(png, Z_DEFAULT_STRATEGY);
  // Adaptive filtering, libpng's default for 8-bit RGB (what OpenImageIO's PNG_NO_FILTERS meant):
  // 62 KB for the default scene, 78 KB with no filter.
  png_set_filter(png, PNG_FILTER_TYPE_BASE, PNG_ALL_FILTERS);
  png_set_IHDR(png, info, png_uint_32(width), png_uint_32(height), 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_set_oFFs(png, info, 0, 0, PNG_OFFSET_PIXEL);
  png_set_sRGB_gAMA_and_cHRM(png, info, PNG_sRGB_INTENT_ABSOLUTE);
  if (textCount > 0) png_set_text(png, info, text, textCount);
  png_write_info(png, info);
  for (int y = 0; y < height; ++y)
    png_write_row(png, const_cast<png_bytep>(codes + size_t(y) * size_t(width) * 3));
  png_write_end(png, info);
  return true;
}

/// Write 8-bit RGB `codes` with `texts` (key, value) as tEXt chunks to `tmpPath`.
void writePngFile(const std::string& path, const std::string& tmpPath, int width, int height,
                  const std::vector<uint8_t>& codes, std::vector<std::pair<std::string, std::string>> texts) {
  std::vector<png_text> text(texts.size());
  for (size_t i = 0; i < texts.size(); ++i) {
    std::memset(&text[i], 0, sizeof(png_text));
    text[i].compression = PNG_TEXT_COMPRESSION_NONE;
    text[i].key = texts[i].first.data();
    text[i].text = texts[i].second.data();
    text[i].text_length = texts[i].second.size();
  }
  FILE* file = std::fopen(tmpPath.c_str(), "wb");
  if (!file) throw ImageError(path + ": cannot open " + tmpPath + " for writing: " + std::strerror(errno));
  PngErrorState state;
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &state, pngError, pngWarning);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  const bool ok =
      png && info && pngWriteCore(png, info, file, width, height, codes.data(), text.data(), int(text.size()));
  if (png) png_destroy_write_struct(&png, info ? &info : nullptr);
  const bool closed = std::fclose(file) == 0;
  if (!ok) throw ImageError(path + ": cannot write PNG: " + firstLine(state.message));
  if (!closed) throw ImageError(path + ": cannot finish writing " + tmpPath + ": " + std::strerror(errno));
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
  // Float channels; the attributes are typed, as OpenImageIO wrote them before (capDate, the
  // metadata, the whole JSON).
  Imf::Header header(image.width, image.height);
  // Lossless RLE: a rendered float image barely compresses (zip: 730 KB instead of 795 KB
  // uncompressed at 256x256), and zip took 12.5 ms of a 0.17 s render there, RLE 5 ms (758 KB).
  header.compression() = Imf::RLE_COMPRESSION;
  try {
    for (const std::string& n : names) header.channels().insert(n, Imf::Channel(Imf::FLOAT));
  } catch (const std::exception& e) {
    throw ImageError(path + ": cannot write OpenEXR: " + firstLine(e.what()));
  }
  putAttribute(header, "capDate", Imf::StringAttribute(capDate()));
  for (const MetadataAttribute& a : metadataAttributes(metadata)) setTypedAttribute(header, a);
  if (!metadata.is_null()) {
    const std::string whole = metadata.dump();
    if (whole.size() <= kMaxExrMetadataBytes) putAttribute(header, "voxcone:metadata", Imf::StringAttribute(whole));
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
  const float* data = layers.empty() ? reinterpret_cast<const float*>(image.pixels.data()) : interleaved.data();
  const size_t xStride = names.size() * sizeof(float), yStride = xStride * size_t(image.width);
  atomicWrite<ImageError>(
      path,
      [&](const std::string& tmpPath) {
        try {
          Imf::FrameBuffer frame;
          for (size_t c = 0; c < names.size(); ++c)
            frame.insert(names[c], Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(const_cast<float*>(data + c)),
                                              xStride, yStride));
          Imf::OutputFile file(tmpPath.c_str(), header);
          file.setFrameBuffer(frame);
          file.writePixels(image.height);
        } catch (const std::exception& e) {
          throw ImageError(path + ": cannot write OpenEXR: " + firstLine(e.what()));
        }
      },
      set);
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
  // PNG text has no types: every value as text (strings bare, others as JSON).
  std::vector<std::pair<std::string, std::string>> texts;
  if (metadata.is_object()) {
    if (metadata.contains("voxcone_version") && metadata["voxcone_version"].is_string())
      texts.emplace_back("Software", "voxcone " + metadata["voxcone_version"].get<std::string>());
    for (const MetadataAttribute& a : metadataAttributes(metadata))
      texts.emplace_back(a.name, a.value.is_string() ? a.value.get<std::string>() : a.value.dump());
  }
  atomicWrite<ImageError>(
      path, [&](const std::string& tmpPath) { writePngFile(path, tmpPath, image.width, image.height, codes, texts); },
      set);
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

namespace {

/// A decoded file before the conversion to linear RGB: every channel of every pixel as float
/// (integer codes divided by their maximum, as OpenImageIO converts them), and how its values
/// are encoded, named as OpenImageIO 2.4 named it ("oiio:ColorSpace", "oiio:Gamma").
struct DecodedImage {
  int width = 0, height = 0, channels = 0;
  std::vector<float> values;
  std::vector<std::string> names;  ///< channel names (EXR; empty otherwise)
  bool integer = false;            ///< integer codes: display-encoded unless the file says linear
  std::string colorSpace;          ///< "sRGB", "linear", "GammaX.Y" or ""
  bool hasGamma = false;
  float gamma = 0.0f;
};

bool equalsNoCase(const std::string& a, const char* b) { return a.size() == std::strlen(b) && startsWithNoCase(a, b); }

// ---- OpenEXR

/// A channel in the order OpenImageIO 2.4 presents an EXR's channels: by layer, then R, G, B
/// (X, Y, Z where a layer has X and Y or Z), A, Z, ... before other names.
struct ExrChannel {
  std::string name, layer, suffix;
  Imf::PixelType type;
  int special = 10000;
};

void sortExrChannels(std::vector<ExrChannel>& channels) {
  static const char* const kSpecial[] = {"R",  "Red", "G",  "Green", "B",  "Blue", "Y",     "real",  "imag", "A", "Alpha",
                                         "AR", "RA",  "AG", "GA",    "AB", "BA",   "Z",     "Depth", "Zback"};
  static const char* const kSpecialXyz[] = {"R",     "Red", "G",  "Green", "B",  "Blue", "X",  "Y",  "Z",     "real",
                                            "imag",  "A",   "Alpha", "AR", "RA", "AG",   "GA", "AB", "BA", "Depth", "Zback"};
  std::stable_sort(channels.begin(), channels.end(),
                   [](const ExrChannel& a, const ExrChannel& b) { return a.layer < b.layer; });
  for (auto begin = channels.begin(); begin != channels.end();) {
    auto end = begin + 1;
    while (end != channels.end() && end->layer == begin->layer) ++end;
    const auto has = [&](const char* s) {
      return std::any_of(begin, end, [&](const ExrChannel& c) { return equalsNoCase(c.suffix, s); });
    };
    const bool xyz = has("X") && (has("Y") || has("Z"));
    for (auto it = begin; it != end; ++it) {
      const auto pick = [&](const auto& list) {
        for (size_t i = 0; i < std::size(list); ++i)
          if (equalsNoCase(it->suffix, list[i])) return int(i);
        return 10000;
      };
      it->special = xyz ? pick(kSpecialXyz) : pick(kSpecial);
    }
    std::sort(begin, end, [](const ExrChannel& a, const ExrChannel& b) {
      if (a.special != b.special) return a.special < b.special;
      return a.suffix < b.suffix;
    });
    begin = end;
  }
}

DecodedImage readExr(const std::string& path) {
  DecodedImage out;
  try {
    Imf::InputFile file(path.c_str());
    const Imf::Header& header = file.header();
    const Imath::Box2i window = header.dataWindow();
    const int64_t width = int64_t(window.max.x) - window.min.x + 1, height = int64_t(window.max.y) - window.min.y + 1;
    std::vector<ExrChannel> channels;
    for (auto it = header.channels().begin(); it != header.channels().end(); ++it) {
      if (it.channel().xSampling != 1 || it.channel().ySampling != 1)
        throw ImageError(path + ": cannot read image: subsampled channel " + it.name() + " is not supported");
      ExrChannel c;
      c.name = it.name();
      const size_t dot = c.name.rfind('.');
      c.layer = dot == std::string::npos ? std::string() : c.name.substr(0, dot);
      c.suffix = dot == std::string::npos ? c.name : c.name.substr(dot + 1);
      c.type = it.channel().type;
      channels.push_back(std::move(c));
    }
    if (width <= 0 || height <= 0 || channels.empty() || width > INT32_MAX || height > INT32_MAX)
      throw ImageError(path + ": image has no pixels (" + std::to_string(width) + "x" + std::to_string(height) + "x" +
                       std::to_string(channels.size()) + ")");
    sortExrChannels(channels);
    out.width = int(width), out.height = int(height), out.channels = int(channels.size());
    out.values.resize(size_t(width) * size_t(height) * channels.size());
    const size_t xStride = channels.size() * sizeof(float), yStride = xStride * size_t(width);
    Imf::FrameBuffer frame;
    for (size_t c = 0; c < channels.size(); ++c) {
      // Half and float channels read as float; 32-bit unsigned ones as themselves, scaled below.
      const Imf::PixelType type = channels[c].type == Imf::UINT ? Imf::UINT : Imf::FLOAT;
      frame.insert(channels[c].name, Imf::Slice::Make(type, out.values.data() + c, window, xStride, yStride));
      out.names.push_back(channels[c].name);
    }
    file.setFrameBuffer(frame);
    file.readPixels(window.min.y, window.max.y);
    for (size_t c = 0; c < channels.size(); ++c) {
      if (channels[c].type != Imf::UINT) continue;
      for (size_t i = c; i < out.values.size(); i += channels.size()) {
        uint32_t u;
        std::memcpy(&u, &out.values[i], sizeof(u));
        out.values[i] = float(u) * (1.0f / float(UINT32_MAX));
      }
    }
  } catch (const ImageError&) {
    throw;
  } catch (const std::exception& e) {
    throw ImageError(path + ": cannot read OpenEXR: " + firstLine(e.what()));
  }
  return out;
}

// ---- PNG

struct PngHeader {
  png_uint_32 width = 0, height = 0;
  int channels = 0, bitDepth = 0;
  size_t storedRowBytes = 0, rowBytes = 0;
  bool srgb = false, hasGamma = false;
  double gamma = 0.0;
  char colorSpaceText[64] = "";  ///< a tEXt "oiio:ColorSpace" (OpenImageIO's own PNGs)
};

/// png_read_info and the transformations OpenImageIO asked for (palette to RGB, low bit
/// depths to 8, tRNS to alpha); false on a libpng error.
bool pngReadHeader(png_structp png, png_infop info, FILE* file, PngHeader* h) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_init_io(png, file);
  png_read_info(png, info);
  h->storedRowBytes = png_get_rowbytes(png, info);
  png_set_expand(png);
  png_set_interlace_handling(png);
  png_read_update_info(png, info);
  h->width = png_get_image_width(png, info);
  h->height = png_get_image_height(png, info);
  h->channels = png_get_channels(png, info);
  h->bitDepth = png_get_bit_depth(png, info);
  h->rowBytes = png_get_rowbytes(png, info);
  int intent = 0;
  h->srgb = png_get_sRGB(png, info, &intent) != 0;
  h->hasGamma = png_get_gAMA(png, info, &h->gamma) != 0 && h->gamma > 0.0;
  png_textp text = nullptr;
  const int count = png_get_text(png, info, &text, nullptr);
  for (int i = 0; i < count; ++i)
    if (text[i].key && text[i].text && strcasecmp(text[i].key, "oiio:ColorSpace") == 0)
      std::snprintf(h->colorSpaceText, sizeof(h->colorSpaceText), "%s", text[i].text);
  return true;
}

bool pngReadRows(png_structp png, png_bytepp rows) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_read_image(png, rows);
  return true;
}

DecodedImage readPng(const std::string& path) {
  FILE* file = std::fopen(path.c_str(), "rb");
  if (!file) throw ImageError(path + ": cannot open: " + std::strerror(errno));
  std::error_code ec;
  const uintmax_t fileSize = fs::file_size(path, ec);
  PngErrorState state;
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &state, pngError, pngWarning);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  PngHeader h;
  DecodedImage out;
  std::string error;
  try {
    if (!png || !info) {
      error = "cannot create libpng structures";
    } else if (!pngReadHeader(png, info, file, &h)) {
      error = std::string("cannot read PNG: ") + state.message;
    } else if (h.width == 0 || h.height == 0 || h.channels < 1 || h.channels > 4 ||
               (h.bitDepth != 8 && h.bitDepth != 16) || h.rowBytes < size_t(h.width) * size_t(h.channels)) {
      error = "unsupported PNG layout (" + std::to_string(h.width) + "x" + std::to_string(h.height) + ", " +
              std::to_string(h.channels) + " channels of " + std::to_string(h.bitDepth) + " bits)";
    } else if (double(h.storedRowBytes + 1) * double(h.height) > 1100.0 * double(fileSize) + double(1 << 20)) {
      // More pixels than deflate (at most 1032:1) could have packed into the file.
      error = "truncated or corrupt PNG: " + std::to_string(h.width) + "x" + std::to_string(h.height) + " pixels in " +
              std::to_string(fileSize) + " bytes";
    } else {
      std::vector<png_byte> bytes(h.rowBytes * h.height);
      std::vector<png_bytep> rows(h.height);
      for (png_uint_32 y = 0; y < h.height; ++y) rows[y] = bytes.data() + size_t(y) * h.rowBytes;
      if (!pngReadRows(png, rows.data())) {
        error = std::string("cannot read PNG: ") + state.message;
      } else {
        out.width = int(h.width), out.height = int(h.height), out.channels = h.channels;
        out.integer = true;
        const size_t perRow = size_t(h.width) * size_t(h.channels);
        out.values.resize(perRow * h.height);
        for (png_uint_32 y = 0; y < h.height; ++y) {
          const png_byte* row = rows[y];
          float* dst = out.values.data() + size_t(y) * perRow;
          if (h.bitDepth == 16) {
            for (size_t i = 0; i < perRow; ++i)
              dst[i] = float(unsigned(row[2 * i]) << 8 | unsigned(row[2 * i + 1])) * (1.0f / 65535.0f);
          } else {
            for (size_t i = 0; i < perRow; ++i) dst[i] = float(row[i]) * (1.0f / 255.0f);
          }
        }
        // OpenImageIO 2.4's reading of the colour chunks: sRGB wins, then gAMA (its exponent
        // rounded to hundredths, 1 meaning linear), else sRGB; a tEXt oiio:ColorSpace last.
        if (h.srgb) {
          out.colorSpace = "sRGB";
        } else if (h.hasGamma) {
          float g = float(1.0 / h.gamma);
          g = std::round(float(100.0 * double(g))) / 100.0f;
          out.hasGamma = true;
          out.gamma = g;
          char name[32];
          std::snprintf(name, sizeof(name), "Gamma%.2g", double(g));
          out.colorSpace = g == 1.0f ? "linear" : name;
        } else {
          out.colorSpace = "sRGB";
        }
        if (h.colorSpaceText[0]) out.colorSpace = h.colorSpaceText;
      }
    }
  } catch (const std::bad_alloc&) {
    error = "image too large (" + std::to_string(h.width) + "x" + std::to_string(h.height) + ")";
  }
  if (png) png_destroy_read_struct(&png, info ? &info : nullptr, nullptr);
  std::fclose(file);
  if (!error.empty()) throw ImageError(path + ": " + firstLine(error));
  return out;
}

// ---- JPEG

struct JpegErrorState {
  jpeg_error_mgr manager;
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX] = "unknown libjpeg error";
};

void jpegErrorExit(j_common_ptr info) {
  auto* state = reinterpret_cast<JpegErrorState*>(info->err);
  (*info->err->format_message)(info, state->message);
  std::longjmp(state->jump, 1);
}

/// Warnings are ignored (as OpenImageIO did), but for the end of the data before the image's:
/// libjpeg would fill the rest with grey; a truncated file is an error.
void jpegEmitMessage(j_common_ptr info, int level) {
  if (level < 0 && info->err->msg_code == JWRN_JPEG_EOF) jpegErrorExit(info);
}

struct JpegHeader {
  int width = 0, height = 0, channels = 0;
  bool cmyk = false;
};

bool jpegStart(jpeg_decompress_struct* info, JpegErrorState* state, FILE* file, JpegHeader* h) {
  if (setjmp(state->jump)) return false;
  jpeg_create_decompress(info);
  jpeg_stdio_src(info, file);
  jpeg_read_header(info, TRUE);
  // CMYK (and YCCK) converted to RGB below, as OpenImageIO did.
  h->cmyk = info->jpeg_color_space == JCS_CMYK || info->jpeg_color_space == JCS_YCCK;
  if (h->cmyk) info->out_color_space = JCS_CMYK;
  jpeg_start_decompress(info);
  h->width = int(info->output_width);
  h->height = int(info->output_height);
  h->channels = info->output_components;
  return true;
}

bool jpegReadRows(jpeg_decompress_struct* info, JpegErrorState* state, unsigned char* bytes, size_t rowBytes) {
  if (setjmp(state->jump)) return false;
  while (info->output_scanline < info->output_height) {
    JSAMPROW row = bytes + size_t(info->output_scanline) * rowBytes;
    if (jpeg_read_scanlines(info, &row, 1) != 1) {
      std::snprintf(state->message, sizeof(state->message), "no scanline data");
      return false;
    }
  }
  return true;
}

DecodedImage readJpeg(const std::string& path) {
  FILE* file = std::fopen(path.c_str(), "rb");
  if (!file) throw ImageError(path + ": cannot open: " + std::strerror(errno));
  jpeg_decompress_struct info;
  std::memset(&info, 0, sizeof(info));  // jpeg_destroy_decompress after a failed create: nothing to free
  JpegErrorState state;
  info.err = jpeg_std_error(&state.manager);
  state.manager.error_exit = jpegErrorExit;
  state.manager.emit_message = jpegEmitMessage;
  JpegHeader h;
  DecodedImage out;
  std::string error;
  try {
    if (!jpegStart(&info, &state, file, &h)) {
      error = std::string("cannot read JPEG: ") + state.message;
    } else if (h.width <= 0 || h.height <= 0 || h.channels < 1 || (h.cmyk && h.channels != 4)) {
      error = "unsupported JPEG layout";
    } else {
      const size_t rowBytes = size_t(h.width) * size_t(h.channels);
      std::vector<unsigned char> bytes(rowBytes * size_t(h.height));
      if (!jpegReadRows(&info, &state, bytes.data(), rowBytes)) {
        error = std::string("cannot read JPEG: ") + state.message;
      } else {
        out.width = h.width, out.height = h.height, out.channels = h.cmyk ? 3 : h.channels;
        out.integer = true;
        out.colorSpace = "sRGB";
        const size_t npix = size_t(h.width) * size_t(h.height);
        out.values.resize(npix * size_t(out.channels));
        if (h.cmyk) {
          // OpenImageIO's conversion: inverted CMYK, R = C * K, rounded to a code again.
          for (size_t i = 0; i < npix; ++i) {
            const unsigned char* p = &bytes[4 * i];
            const float k = float(p[3]) * (1.0f / 255.0f);
            for (int c = 0; c < 3; ++c) {
              const float v = float(p[c]) * (1.0f / 255.0f) * k;
              const int code = int(std::min(std::max(v * 255.0f + 0.5f, 0.0f), 255.0f));
              out.values[3 * i + size_t(c)] = float(code) * (1.0f / 255.0f);
            }
          }
        } else {
          for (size_t i = 0; i < out.values.size(); ++i) out.values[i] = float(bytes[i]) * (1.0f / 255.0f);
        }
      }
    }
  } catch (const std::bad_alloc&) {
    error = "image too large (" + std::to_string(h.width) + "x" + std::to_string(h.height) + ")";
  }
  jpeg_destroy_decompress(&info);
  std::fclose(file);
  if (!error.empty()) throw ImageError(path + ": " + firstLine(error));
  return out;
}

}  // namespace

namespace {

const unsigned char kExrMagic[4] = {0x76, 0x2f, 0x31, 0x01};

/// The first 8 bytes of an image file (zeros past its end), which say its format.
std::array<unsigned char, 8> fileMagic(const std::string& path) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) throw ImageError(path + ": no such image file");
  std::array<unsigned char, 8> magic{};
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ImageError(path + ": cannot open: " + std::strerror(errno));
  in.read(reinterpret_cast<char*>(magic.data()), std::streamsize(magic.size()));
  return magic;
}

}  // namespace

std::vector<std::optional<Image>> readImageLayers(const std::string& path, const std::vector<std::string>& prefixes) {
  std::vector<std::optional<Image>> out(prefixes.size());
  if (std::memcmp(fileMagic(path).data(), kExrMagic, 4) != 0) return out;
  const DecodedImage d = readExr(path);
  static const char* const kNames[2][3] = {{"R", "G", "B"}, {"X", "Y", "Z"}};
  for (size_t i = 0; i < prefixes.size(); ++i)
    for (const auto& names : kNames) {
      int at[3] = {-1, -1, -1};
      for (int k = 0; k < 3; ++k)
        for (size_t c = 0; c < d.names.size(); ++c)
          if (d.names[c] == prefixes[i] + names[k]) at[k] = int(c);
      if (at[0] < 0 || at[1] < 0 || at[2] < 0) continue;
      Image img(d.width, d.height);
      for (size_t p = 0; p < img.pixels.size(); ++p)
        for (int k = 0; k < 3; ++k) img.pixels[p][k] = d.values[p * size_t(d.channels) + size_t(at[k])];
      out[i] = std::move(img);
      break;
    }
  return out;
}

Image readImage(const std::string& path) {
  // The format by the file's signature; the extension only names what a file should have been.
  const std::array<unsigned char, 8> bytes = fileMagic(path);
  const unsigned char* magic = bytes.data();
  static const unsigned char kPng[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  DecodedImage d;
  if (std::memcmp(magic, kExrMagic, 4) == 0) {
    d = readExr(path);
  } else if (std::memcmp(magic, kPng, 8) == 0) {
    d = readPng(path);
  } else if (magic[0] == 0xff && magic[1] == 0xd8 && magic[2] == 0xff) {
    d = readJpeg(path);
  } else {
    const std::string ext = lowerExtension(path);
    const char* what = ext == ".exr" ? "OpenEXR" : ext == ".png" ? "PNG" : ext == ".jpg" || ext == ".jpeg" ? "JPEG" : nullptr;
    if (what) throw ImageError(path + ": cannot read image: not a valid " + std::string(what) + " file");
    throw ImageError(path + ": cannot read image: unsupported format (voxcone reads OpenEXR, PNG and JPEG files)");
  }
  const int nch = d.channels;
  if (d.width <= 0 || d.height <= 0 || nch <= 0)
    throw ImageError(path + ": image has no pixels (" + std::to_string(d.width) + "x" + std::to_string(d.height) +
                     "x" + std::to_string(nch) + ")");
  const size_t npix = static_cast<size_t>(d.width) * static_cast<size_t>(d.height);

  // Integer files are display-encoded unless they say they are linear: PNG and JPEG are "sRGB"
  // (or nothing), PNG with a gAMA chunk "GammaX.Y" with its exponent.
  const std::string& colorSpace = d.colorSpace;
  const bool integer = d.integer;
  enum class Decode { None, Srgb, Gamma } decode = Decode::None;
  float gamma = 1.0f;
  if (integer) {
    if (colorSpace.empty() || startsWithNoCase(colorSpace, "srgb")) {
      decode = Decode::Srgb;
    } else if (startsWithNoCase(colorSpace, "gamma")) {
      gamma = d.hasGamma ? d.gamma : 2.2f;
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
  // G and B (an EXR with AOV layers), else the first three. Alpha is dropped, the colour not
  // premultiplied by it.
  int rgb[3] = {0, 1, 2};
  if (nch > 3) {
    const auto& names = d.names;
    const auto find = [&](const char* n) { return int(std::find(names.begin(), names.end(), n) - names.begin()); };
    const int r = find("R"), g = find("G"), b = find("B"), count = int(names.size());
    if (r < count && g < count && b < count) rgb[0] = r, rgb[1] = g, rgb[2] = b;
  }
  Image image(d.width, d.height);
  image.displayEncoded = integer;
  for (size_t i = 0; i < npix; ++i) {
    const float* p = &d.values[i * static_cast<size_t>(nch)];
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

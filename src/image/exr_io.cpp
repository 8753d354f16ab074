// OpenEXR files through OpenEXR's C++ library (image_io.h): float RGB with AOV layers and
// typed metadata attributes written; any EXR read, its channels in OpenImageIO 2.4's order.

#include "image_io_impl.h"

#include "voxcone/core/error.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFloatAttribute.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfIntAttribute.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <iterator>
#include <string>
#include <vector>

namespace voxcone {

using namespace image_io;

namespace {

/// Largest JSON dump stored whole in the "voxcone:metadata" EXR attribute. OpenEXR headers have
/// no hard limit, but readers (and OpenEXR's own sanity checks) dislike huge headers; the
/// per-key attributes carry the same content anyway.
constexpr size_t kMaxExrMetadataBytes = 64 * 1024;

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

/// A channel in the order OpenImageIO 2.4 presents an EXR's channels: by layer, then R, G, B
/// (X, Y, Z where a layer has X and Y or Z), A, Z, ... before other names.
struct ExrChannel {
  std::string name, layer, suffix;
  Imf::PixelType type;
  int special = 10000;
};

/// Sort `channels` into OpenImageIO 2.4's order (ExrChannel).
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
  writeImageAtomic(
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

namespace image_io {

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

}  // namespace image_io

}  // namespace voxcone

/// \file image_io.cpp
/// Image files: what every format shares (checks, sRGB, metadata attributes), writing by
/// extension and reading by signature. The formats live apart: OpenEXR through its C++ library
/// (exr_io.cpp), PNG through libpng (png_io.cpp) and JPEG through libjpeg (jpeg_io.cpp),
/// directly: OpenImageIO, which the executable used to link for this, pulls in ~260 shared
/// libraries (ffmpeg, gdcm, opencv, ...) whose loading and relocation took 0.35 s of every run's
/// start. Reading keeps OpenImageIO 2.4's conventions where they decide the pixels (the tests
/// read the same files with both): EXR channels in its order, integer codes scaled by the float
/// 1/max, PNG colour from sRGB / gAMA chunks. Output sets and JSON: output_set.cpp.

#include "image_io_impl.h"

#include "voxcone/core/error.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

namespace voxcone {

namespace image_io {

std::string firstLine(const std::string& text) {
  const size_t end = text.find_first_of("\r\n");
  std::string line = text.substr(0, end);
  return line.empty() ? std::string("unknown error") : line;
}

void checkImage(const std::string& path, const Image& image) {
  if (image.width <= 0 || image.height <= 0 ||
      image.pixels.size() != static_cast<size_t>(image.width) * static_cast<size_t>(image.height))
    throw ImageError(path + ": cannot write an empty or inconsistent image (" + std::to_string(image.width) + "x" +
                     std::to_string(image.height) + ", " + std::to_string(image.pixels.size()) + " pixels)");
}

std::string lowerExtension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
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

bool equalsNoCase(const std::string& a, const char* b) { return a.size() == std::strlen(b) && startsWithNoCase(a, b); }

}  // namespace image_io

using namespace image_io;

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

/// The first 8 bytes of an image file (zeros past its end), which say its format.
std::array<unsigned char, 8> fileMagic(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw ImageError(path + ": no such image file");
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

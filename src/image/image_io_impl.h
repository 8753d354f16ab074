#pragma once
/// \file image_io_impl.h
/// Image files' internals, shared by their files: the checks and names every format uses, the
/// atomic write of an image (image_io.cpp, output_set.cpp), and the decoded file each reader
/// returns (exr_io.cpp, png_io.cpp, jpeg_io.cpp) before readImage converts it to linear RGB.
/// Not a public header.

#include "voxcone/image/image_io.h"

#include <functional>
#include <string>
#include <vector>

namespace voxcone {
namespace image_io {

/// First line of a library's error text (OpenEXR's messages can span several lines).
std::string firstLine(const std::string& text);
/// Throws ImageError unless `image` has pixels, as many as its size says.
void checkImage(const std::string& path, const Image& image);
/// Lower-case extension of `path` including the dot ("" if none).
std::string lowerExtension(const std::string& path);
/// Whether `s` starts with `prefix`, ignoring ASCII case.
bool startsWithNoCase(const std::string& s, const char* prefix);
/// Whether `a` equals `b`, ignoring ASCII case.
bool equalsNoCase(const std::string& a, const char* b);

/// writeFileAtomic throwing ImageError (as image writes document); with `set`, the temporary
/// joins the set instead of being renamed now.
void writeImageAtomic(const std::string& path, const std::function<void(const std::string& tmpPath)>& writer,
                      OutputSet* set);

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

/// The first 4 bytes of every OpenEXR file.
inline const unsigned char kExrMagic[4] = {0x76, 0x2f, 0x31, 0x01};

/// Decode an OpenEXR file: its channels in OpenImageIO 2.4's order, half and float as float,
/// 32-bit unsigned scaled by 1 / (2^32 - 1). Throws ImageError.
DecodedImage readExr(const std::string& path);
/// Decode a PNG file (8 or 16 bits, 1 to 4 channels after expanding palettes and low depths),
/// with its colour space from its sRGB, gAMA or tEXt chunks. Throws ImageError.
DecodedImage readPng(const std::string& path);
/// Decode a JPEG file (CMYK converted to RGB as OpenImageIO did), sRGB. Throws ImageError.
DecodedImage readJpeg(const std::string& path);

}  // namespace image_io
}  // namespace voxcone

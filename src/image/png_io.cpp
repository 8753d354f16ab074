// PNG files through libpng (image_io.h): 8-bit sRGB written with metadata as tEXt chunks; 8- and
// 16-bit read, their colour space from the sRGB, gAMA and tEXt chunks as OpenImageIO 2.4 read it.

#include "image_io_impl.h"

#include "voxcone/core/error.h"

#include <png.h>
#include <strings.h>
#include <zlib.h>
#include <nlohmann/json.hpp>

#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

namespace voxcone {

using namespace image_io;

namespace {

// libpng reports errors by longjmp: each function that calls it and may jump holds nothing with
// a destructor; the callers own every buffer.

/// libpng's error pointer: the message of the error that ended a read or write.
struct PngErrorState {
  char message[256] = "unknown libpng error";
};

/// libpng's error handler: keeps the message and jumps back to the caller's setjmp.
void pngError(png_structp png, png_const_charp message) {
  auto* state = static_cast<PngErrorState*>(png_get_error_ptr(png));
  if (state) std::snprintf(state->message, sizeof(state->message), "%s", message ? message : "libpng error");
  png_longjmp(png, 1);
}

/// libpng's warnings are ignored.
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

/// What pngReadHeader finds in a PNG's header and chunks, after the transformations it asks for.
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

/// png_read_image into `rows`; false on a libpng error.
bool pngReadRows(png_structp png, png_bytepp rows) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_read_image(png, rows);
  return true;
}

}  // namespace

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
  writeImageAtomic(
      path, [&](const std::string& tmpPath) { writePngFile(path, tmpPath, image.width, image.height, codes, texts); },
      set);
}

namespace image_io {

DecodedImage readPng(const std::string& path) {
  FILE* file = std::fopen(path.c_str(), "rb");
  if (!file) throw ImageError(path + ": cannot open: " + std::strerror(errno));
  std::error_code ec;
  const uintmax_t fileSize = std::filesystem::file_size(path, ec);
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

}  // namespace image_io

}  // namespace voxcone

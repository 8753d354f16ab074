// JPEG files through libjpeg (image_io.h): read only, CMYK converted to RGB as OpenImageIO did.

#include "image_io_impl.h"

#include "voxcone/core/error.h"

// jpeglib.h needs FILE and size_t declared first.
#include <cstdio>
#include <jpeglib.h>
#include <jerror.h>

#include <algorithm>
#include <cerrno>
#include <csetjmp>
#include <cstring>
#include <string>
#include <vector>

namespace voxcone {

using namespace image_io;

namespace {

// libjpeg reports errors by longjmp: each function that calls it and may jump holds nothing
// with a destructor; the callers own every buffer.

/// libjpeg's error manager with the jump back to the caller and the message of the error.
struct JpegErrorState {
  jpeg_error_mgr manager;
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX] = "unknown libjpeg error";
};

/// libjpeg's error exit: keeps the message and jumps back to the caller's setjmp.
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

/// What jpegStart finds in a JPEG's header.
struct JpegHeader {
  int width = 0, height = 0, channels = 0;
  bool cmyk = false;
};

/// Read the header and start decompressing (CMYK kept as CMYK); false on a libjpeg error.
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

/// Every scanline into `bytes`, rows `rowBytes` apart; false on a libjpeg error.
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

}  // namespace

namespace image_io {

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

}  // namespace image_io

}  // namespace voxcone

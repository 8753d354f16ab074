#pragma once
/// \file tza.h
/// Open Image Denoise's weight files (.tza, "tensor archive", version 2): a table of named
/// tensors (dims, layout "x" or "oihw", fp32 'f' or fp16 'h') at the offset the header gives.
/// Read here into fp32 (our own reader of the published format; OIDN's sources define it).

#include <cstdint>
#include <map>
#include <string>
#include <vector>

namespace voxcone {

/// One tensor of a .tza: its dimensions (a convolution's weights are output channels, input
/// channels, kernel height, kernel width: "oihw"; a bias is "x"), as fp32.
struct TzaTensor {
  std::vector<int> dims;
  std::string layout;
  std::vector<float> values;
  size_t size() const;  ///< the product of dims
};

/// The tensors of a .tza file's bytes by name. A truncated or malformed archive (bad magic,
/// version other than 2, a layout whose length is not ndims, a data type other than 'f' or
/// 'h', data past the end) is an ImageError naming `what` (the file) and what is wrong.
std::map<std::string, TzaTensor> parseTza(const std::vector<uint8_t>& bytes, const std::string& what);
/// parseTza of a file's contents (ImageError where it cannot be read).
std::map<std::string, TzaTensor> readTza(const std::string& path);

/// IEEE 754 binary16 to float (subnormals, infinities and NaNs included).
float halfToFloat(uint16_t h);

}  // namespace voxcone

#pragma once
/// \file image_io.h
/// Image files through OpenImageIO (kept out of this header), all written atomically: the data
/// goes to a temporary file in the target's folder which is renamed over the target, so an
/// interrupted write never leaves a half-written file.

#include "voxcone/image/image.h"

#include <nlohmann/json_fwd.hpp>

#include <functional>
#include <string>

namespace voxcone {

/// Write linear float RGB OpenEXR. Every top-level key of `metadata` becomes an EXR string
/// attribute "voxcone:<key>" (its JSON dump). Throws ImageError.
void writeExr(const std::string& path, const Image& image, const nlohmann::json& metadata);

/// Write an 8-bit sRGB PNG (linear values clamped to [0,1], sRGB OETF, rounded). Throws ImageError.
void writePng(const std::string& path, const Image& image);

/// Write by extension: .exr (float, metadata) or .png (sRGB 8-bit). Throws ImageError.
void writeImage(const std::string& path, const Image& image, const nlohmann::json& metadata);

/// Read any image OpenImageIO reads; 8-bit sRGB formats (PNG, JPEG) are converted to linear.
/// Throws ImageError with a one-line message when the file is missing or unreadable.
Image readImage(const std::string& path);

/// Write pretty JSON (2-space indent) atomically. Throws Error.
void writeJsonAtomic(const std::string& path, const nlohmann::json& value);

/// Call `writer(tmpPath)` to write a temporary file next to `path` (same extension), then
/// rename it over `path`. The temporary is removed if `writer` throws. Throws Error.
void writeFileAtomic(const std::string& path, const std::function<void(const std::string& tmpPath)>& writer);

/// sRGB OETF (IEC 61966-2-1) of a linear value, input clamped to [0,1].
float linearToSrgb(float linear);
/// Inverse of linearToSrgb.
float srgbToLinear(float encoded);
/// 8-bit sRGB code value of a linear value: round(255 * linearToSrgb(clamp(v))).
int toSrgb8(float linear);

}  // namespace voxcone

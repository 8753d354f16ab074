#pragma once
/// \file image_io.h
/// Image files (OpenEXR, PNG, JPEG; their libraries kept out of this header), all written
/// atomically: the data goes to a temporary file in the target's folder which is renamed over
/// the target (core/file_io.h), so an interrupted write never leaves a half-written file.

#include "voxcone/image/image.h"

#include <nlohmann/json.hpp>

#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

namespace voxcone {

/// Files that appear together or not at all: add() writes each to a temporary beside its path
/// (temporaryPathFor, core/file_io.h); commit() renames them, the one named `last` (the sidecar
/// that marks a set complete) after the others. A failed write throws and leaves nothing; a set
/// destroyed before commit() removes its temporaries; a rename that fails removes the files
/// renamed before it. (A process killed between two renames leaves the set without its last
/// file, which is what marks it incomplete; its temporaries are removed by the next write.)
/// add() may be called from several threads.
class OutputSet {
public:
  OutputSet() = default;
  OutputSet(const OutputSet&) = delete;
  OutputSet& operator=(const OutputSet&) = delete;
  ~OutputSet();
  void add(const std::string& path, const std::function<void(const std::string& tmpPath)>& writer);
  void commit(const std::string& last);

private:
  struct Entry {
    std::string path, tmp;
  };
  std::vector<Entry> m_entries;
  std::mutex m_mutex;
  bool m_committed = false;
};

/// Write linear float RGB OpenEXR, with `layers` as further float channels (AOVs). `metadata`
/// becomes typed attributes (metadataAttributes: voxcone:method a string, voxcone:settings.spp
/// an int, voxcone:timings.render_seconds a float) plus the whole of it as JSON in
/// "voxcone:metadata". Atomic, or part of `set`. Throws ImageError.
void writeExr(const std::string& path, const Image& image, const nlohmann::json& metadata, OutputSet* set = nullptr,
              const std::vector<ImageLayer>& layers = {});

/// Write an 8-bit sRGB PNG (linear values clamped to [0,1], sRGB OETF, rounded). `metadata`'s
/// attributes become PNG tEXt chunks (PNG text has no types: each value as text), with
/// Software naming voxcone. Atomic, or part of `set`. Throws ImageError.
void writePng(const std::string& path, const Image& image, OutputSet* set = nullptr,
              const nlohmann::json& metadata = nullptr);

/// One attribute of an image's metadata: the JSON path joined by dots under "voxcone:", and a
/// scalar value (string, integer, float or bool).
struct MetadataAttribute {
  std::string name;
  nlohmann::json value;
};
/// `metadata` flattened into attributes: objects are descended (to 4 levels), scalars kept
/// with their type, arrays and deeper objects stored as their JSON text, nulls left out.
std::vector<MetadataAttribute> metadataAttributes(const nlohmann::json& metadata);

/// Write by extension: .exr (float, metadata) or .png (sRGB 8-bit). Throws ImageError.
void writeImage(const std::string& path, const Image& image, const nlohmann::json& metadata);

/// Read an OpenEXR, PNG or JPEG file (by its signature, whatever its extension); integer formats
/// (PNG, JPEG) are converted to linear (sRGB, or a PNG's gAMA exponent). Throws ImageError with a
/// one-line message when the file is missing, unreadable, truncated or of another format.
Image readImage(const std::string& path);
/// The three channels `prefix`R/G/B or `prefix`X/Y/Z of an OpenEXR file (AOV layers voxcone
/// writes: "Albedo.", "Ns.") as images, one per prefix, from one decode of the file; nullopt
/// where the file has no such layer (or is not an EXR). Throws ImageError where the file
/// cannot be read.
std::vector<std::optional<Image>> readImageLayers(const std::string& path, const std::vector<std::string>& prefixes);

/// Write pretty JSON (2-space indent) atomically, or as part of `set`. Throws Error.
void writeJsonAtomic(const std::string& path, const nlohmann::json& value, OutputSet* set = nullptr);

/// sRGB OETF (IEC 61966-2-1) of a linear value, input clamped to [0,1].
float linearToSrgb(float linear);
/// Inverse of linearToSrgb.
float srgbToLinear(float encoded);
/// 8-bit sRGB code value of a linear value: round(255 * linearToSrgb(clamp(v))).
int toSrgb8(float linear);

}  // namespace voxcone

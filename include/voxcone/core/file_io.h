#pragma once
/// \file file_io.h
/// Atomic file writes: the data goes to a temporary file in the target's folder which is renamed
/// over the target, so that an interrupted write never leaves a half-written file. Every output
/// file voxcone writes (images, sidecars, fields, studies, batch tables) goes this way.

#include <functional>
#include <string>

namespace voxcone {

/// The temporary a write of `path` goes through: ".<stem>.tmp-<pid>-<n><ext>" in its folder,
/// hidden, unique within the process (n counts every call), with the target's extension.
/// Temporaries of the same target left by a process that no longer exists (killed mid-write)
/// are removed first. Throws Error when `path` names no file or its folder does not exist.
std::string temporaryPathFor(const std::string& path);

/// Call `writer(tmpPath)` to write a temporary file next to `path` (temporaryPathFor), then
/// rename it over `path`. The temporary is removed if `writer` throws. Throws Error.
void writeFileAtomic(const std::string& path, const std::function<void(const std::string& tmpPath)>& writer);

}  // namespace voxcone

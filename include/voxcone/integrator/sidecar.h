#pragma once
/// \file sidecar.h
/// The JSON sidecar `voxcone render` writes beside its image (STEM.json), and the metadata of
/// the image files themselves: what the image was made from (the scene and its input files,
/// hashed), how (method, settings, integrator settings), where (command line, executable,
/// working directory), and what it cost (timings per stage, statistics, peak memory), so that
/// studies and plots read JSON, never logs.

#include "voxcone/integrator/integrator.h"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace voxcone {

class Accel;

/// Every input file of a render (Scene::inputFiles: the scene first, then its meshes and
/// includes) with its role ("scene", "mesh" or "include"), absolute path, size and XXH3-128
/// hash as read (core/hash.h: `xxhsum -H2` checks a file against it). Throws Error where a
/// file cannot be read.
nlohmann::json sidecarInputs(const std::vector<std::string>& inputFiles);

/// Seconds per stage of a render before its pixels, as the sidecar's "timings" records them.
struct RenderTimings {
  double load = 0.0;     ///< reading the scene
  double build = 0.0;    ///< building the accelerator
  double pilot = 0.0;    ///< a progressive render's control pixels (progressive.h)
  double prepare = 0.0;  ///< the integrator's prepare (photons, voxels; every pass's)
};

/// What a render's sidecar records: the run (where and from what), the render (what and how),
/// and its reports.
struct RenderRecord {
  std::string version;                   ///< voxcone's
  std::string scene;                     ///< the scene file's absolute path, or "built-in:NAME"
  std::vector<std::string> commandLine;  ///< as main received it
  std::string executable;                ///< the running executable's path
  std::string workingDirectory;
  nlohmann::json inputs;                 ///< sidecarInputs
  int threads = 0;                       ///< threads the render ran on
  const Scene* sceneData = nullptr;      ///< the scene rendered (its statistics)
  const Accel* accel = nullptr;          ///< its accelerator (its statistics)
  const Integrator* integrator = nullptr;  ///< the integrator (its settings and statistics)
  /// The settings rendered with; spp is the samples the image holds (RenderResult::completedSpp
  /// where the render is partial, the passes' where it is progressive).
  RenderSettings settings;
  int requestedSpp = 0;                  ///< the spp asked for (recorded where the render is partial)
  const RenderResult* result = nullptr;  ///< the image's pixels' times, samples, layers, filter statistics
  RenderTimings timings;
  nlohmann::json progressiveReport;      ///< ProgressiveResult::report, null where not progressive
  /// --denoise: the weights' file name and the seconds ("seconds", "input_seconds",
  /// "network_seconds", "output_seconds"); null where not denoised.
  nlohmann::json denoiseReport;
};

/// The sidecar of `record` as the image files' metadata take it (before they are written).
/// `record`'s pointers must be set. Keys are snake_case: voxcone_version, scene, command_line,
/// executable, working_directory, inputs, method, settings, seed, aovs, partial and
/// requested_spp (a partial render), timings, auto (progressive), denoise, stats.
nlohmann::json renderSidecar(const RenderRecord& record);

/// Add to `sidecar` what is known once the image files are written: their writing's seconds
/// (both files', and the EXR's alone), the whole run's seconds, the process's peak resident
/// memory (bytes) and the files' paths.
void addWrittenOutputs(nlohmann::json& sidecar, double writeSeconds, double exrSeconds, double totalSeconds,
                       const std::string& exrPath, const std::string& pngPath);

}  // namespace voxcone

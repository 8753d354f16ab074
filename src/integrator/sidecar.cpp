// The render's JSON sidecar (sidecar.h).

#include "voxcone/integrator/sidecar.h"

#include "voxcone/accel/accel.h"
#include "voxcone/core/hash.h"
#include "voxcone/core/sampler.h"
#include "voxcone/core/timer.h"

#include <filesystem>

namespace voxcone {

nlohmann::json sidecarInputs(const std::vector<std::string>& inputFiles) {
  nlohmann::json inputs = nlohmann::json::array();
  for (size_t i = 0; i < inputFiles.size(); ++i) {
    const std::string& f = inputFiles[i];
    uint64_t bytes = 0;
    const std::string hash = fileXxh128(f, &bytes);
    const std::string ext = std::filesystem::path(f).extension().string();
    inputs.push_back({{"role", i == 0 ? "scene" : ext == ".ply" || ext == ".obj" ? "mesh" : "include"},
                      {"path", std::filesystem::absolute(f).lexically_normal().string()},
                      {"bytes", bytes},
                      {"xxh128", hash}});
  }
  return inputs;
}

nlohmann::json renderSidecar(const RenderRecord& r) {
  const RenderSettings& settings = r.settings;
  const RenderResult& result = *r.result;
  nlohmann::json meta;
  // Where the image was made, and from what.
  meta["voxcone_version"] = r.version;
  meta["scene"] = r.scene;
  meta["command_line"] = r.commandLine;
  meta["executable"] = r.executable;
  meta["working_directory"] = r.workingDirectory;
  meta["inputs"] = r.inputs;
  // How.
  meta["method"] = settings.method;
  meta["settings"] = {{"width", settings.width}, {"height", settings.height}, {"spp", settings.spp},
                      {"max_depth", settings.maxDepth}, {"seed", settings.seed},
                      {"sampler", samplerNames()[size_t(settings.sampler)]},
                      {"light_sampler", settings.lightTree ? "tree" : "power"},
                      {"light_split", settings.lightTree ? settings.lightSplitDeg : 0.0f}, {"threads", r.threads},
                      {"denoise", settings.denoise},
                      {"integrator", r.integrator->settingsJson()}};
  meta["seed"] = settings.seed;
  if (!result.layers.empty()) {
    nlohmann::json layers = nlohmann::json::object();
    for (const ImageLayer& l : result.layers) layers[l.name] = l.channels;
    meta["aovs"] = layers;
  }
  if (result.partial) {
    meta["partial"] = true;
    meta["requested_spp"] = r.requestedSpp;
  }
  // What it cost.
  meta["timings"] = {{"load_seconds", r.timings.load}, {"build_seconds", r.timings.build},
                     {"pilot_seconds", r.timings.pilot}, {"prepare_seconds", r.timings.prepare},
                     {"render_seconds", result.seconds}, {"render_stage_seconds", result.stageSeconds}};
  if (!r.progressiveReport.is_null()) meta["auto"] = r.progressiveReport;
  if (!r.denoiseReport.is_null()) {
    meta["denoise"] = r.denoiseReport;
    meta["timings"]["denoise_seconds"] = r.denoiseReport["seconds"];
  }
  meta["stats"] = {{"scene", r.sceneData->statsJson()}, {"accel", r.accel->statsJson()},
                   {"integrator", r.integrator->statsJson()},
                   {"samples", result.samples}, {"invalid_samples", result.invalidSamples},
                   {"indirect_filter", result.filterStats}};
  return meta;
}

void addWrittenOutputs(nlohmann::json& sidecar, double writeSeconds, double exrSeconds, double totalSeconds,
                       const std::string& exrPath, const std::string& pngPath) {
  sidecar["timings"]["write_seconds"] = writeSeconds;
  sidecar["timings"]["write_exr_seconds"] = exrSeconds;
  sidecar["timings"]["total_seconds"] = totalSeconds;
  sidecar["peak_rss_bytes"] = peakRssBytes();
  sidecar["outputs"] = {{"exr", exrPath}, {"png", pngPath}};
}

}  // namespace voxcone

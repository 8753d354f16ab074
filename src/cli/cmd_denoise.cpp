/// \file cmd_denoise.cpp
/// `voxcone denoise IN.exr -o OUT.exr`: Open Image Denoise's RT network (denoise/denoiser.h) on
/// a render, with the albedo and normal layers `render --aov albedo,normal` writes beside it
/// (or given as files), else the colour alone.

#include "cli_util.h"
#include "commands.h"

#include "voxcone/core/error.h"
#include "voxcone/core/parallel.h"
#include "voxcone/core/timer.h"
#include "voxcone/denoise/denoiser.h"
#include "voxcone/image/image_io.h"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <tuple>
#include <vector>

namespace voxcone {

namespace {

struct DenoiseArgs {
  std::string input, output, albedo, normal, weights;
  std::string aux = "auto";
  int threads = 0;
};

void runDenoise(const DenoiseArgs& a) {
  Timer total;
  const ThreadLimit threads(a.threads);
  const std::string ext = std::filesystem::path(a.output).extension().string();
  if (ext != ".exr" && ext != ".png")
    throw SettingsError("-o " + a.output + ": unknown extension '" + ext + "' (use .exr or .png)");
  const Image color = readImage(a.input);
  if (color.displayEncoded)
    throw SettingsError(a.input + " is an 8-bit display image; the denoiser takes a linear HDR render (.exr)");
  // The auxiliary images: the files given, else the input's own layers, read in one decode.
  std::optional<Image> albedo, normal;
  if (a.aux != "none") {
    std::vector<std::optional<Image>> layers(2);
    if (a.albedo.empty() || a.normal.empty()) layers = readImageLayers(a.input, {"Albedo.", "Ns."});
    albedo = a.albedo.empty() ? std::move(layers[0]) : std::optional<Image>(readImage(a.albedo));
    normal = a.normal.empty() ? std::move(layers[1]) : std::optional<Image>(readImage(a.normal));
  }
  if (a.aux == "albedo") normal.reset();
  if (normal && !albedo) {
    if (!a.normal.empty()) throw SettingsError("--normal needs --albedo too (OIDN has no normal-only filter)");
    normal.reset();
  }
  for (const auto& [img, given, what] : {std::tuple{&albedo, &a.albedo, "albedo"}, std::tuple{&normal, &a.normal, "normal"}})
    if (*img && given->empty()) std::printf("denoise: the %s from %s's layer\n", what, a.input.c_str());
  const LoadedDenoiser d = loadDenoiser(albedo.has_value(), normal.has_value(), a.weights);
  DenoiseTimings tm;
  const Image out = d.denoiser.denoise(color, albedo ? &*albedo : nullptr, normal ? &*normal : nullptr, &tm);
  const nlohmann::json meta = {{"denoised", a.input},
                               {"denoiser", {{"weights", std::filesystem::path(d.weightsPath).filename().string()},
                                             {"input_seconds", tm.input},
                                             {"network_seconds", tm.network},
                                             {"output_seconds", tm.output}}}};
  writeImage(a.output, out, meta);
  std::printf("wrote %s (%s; network %.3f s, total %.3f s)\n", a.output.c_str(),
              std::filesystem::path(d.weightsPath).filename().string().c_str(), tm.network, total.seconds());
}

}  // namespace

void addDenoiseCommand(CLI::App& app) {
  auto a = std::make_shared<DenoiseArgs>();
  CLI::App* cmd = app.add_subcommand(
      "denoise", "Denoise an HDR render with Open Image Denoise's RT network (weights: bash tools/fetch_models.sh)");
  cmd->add_option("input", a->input, "The render (linear .exr; its Albedo and Ns layers are used where present)")
      ->required()
      ->check(nonEmpty());
  cmd->add_option("-o,--output", a->output, "The denoised image (.exr or .png)")->required()->check(nonEmpty());
  cmd->add_option("--albedo", a->albedo, "Albedo image (instead of the input's Albedo layer)");
  cmd->add_option("--normal", a->normal, "Normal image in [-1, 1] (instead of the input's Ns layer; needs an albedo)");
  cmd->add_option("--aux", a->aux, "Auxiliary images: auto (files given, else the input's layers), albedo (no normal), none")
      ->check(CLI::IsMember({"auto", "albedo", "none"}))
      ->default_str("auto");
  cmd->add_option("--weights", a->weights, "Folder of the .tza weights")->default_str("data/models/oidn");
  cmd->add_option("-t,--threads", a->threads, "Threads (0 = all)")->check(CLI::Range(0, 4096));
  cmd->callback([a] { runDenoise(*a); });
}

}  // namespace voxcone

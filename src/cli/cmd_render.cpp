// `voxcone render SCENE`: load, build the HBVH (or --accel), render, write EXR + PNG + JSON sidecar.

#include "cli_util.h"
#include "commands.h"
#include "default_scene.h"
#include "version.h"
#include "voxcone/accel/accel.h"
#include "voxcone/batch/process.h"
#include "voxcone/core/error.h"
#include "voxcone/core/parallel.h"
#include "voxcone/core/timer.h"
#include "voxcone/image/image_io.h"
#include "voxcone/integrator/integrator.h"
#include "voxcone/integrator/progressive.h"
#include "voxcone/integrator/sidecar.h"

#include <nlohmann/json.hpp>
#include <tbb/task_group.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <unistd.h>
#include <exception>
#include <filesystem>
#include <optional>
#include <regex>
#include <tuple>

namespace voxcone {

namespace {

struct RenderOptions {
  std::string scenePath;
  std::string output;
  std::string method;
  int spp = 0;
  std::string resolution;
  std::optional<uint64_t> seed;
  int threads = 0;
  int maxDepth = 0;
  std::string integratorOptions = "{}";
  std::string accel = "hbvh";
  std::string sampler;
  std::string lightSampler;       // --light-sampler: tree or power
  std::optional<float> lightSplit;  // --light-split: the tree's split angle, degrees
  double targetError = 0.0;
  double timeBudget = 0.0;
  std::string field;              // --field: a .vdb to render with (voxcone)
  double memoryBudgetMb = -1.0;   // --memory-budget-mb (voxcone); -1: not given
  bool writePartial = false;      // --write-partial: an interrupted render writes its complete passes
  std::string aovs;               // --aov: layers beside the beauty (integrator.h Aov)
  bool denoise = false;           // --denoise: the beauty through the denoiser (denoise/denoiser.h)
  std::string denoiseWeights;     // --denoise-weights: the .tza folder
  bool quiet = false;
  std::vector<std::string> defines;  // -D NAME=VALUE: Mitsuba scene parameters
};

void parseResolution(const std::string& s, RenderSettings& settings) {
  static const std::regex re("^([0-9]{1,5})x([0-9]{1,5})$");
  std::smatch m;
  if (!std::regex_match(s, m, re)) throw SettingsError("--res expects WIDTHxHEIGHT (e.g. 256x256), got '" + s + "'");
  settings.width = std::stoi(m[1]);
  settings.height = std::stoi(m[2]);
}

/// Throws SettingsError unless <out>.exr, .png and .json can be written: none is a directory,
/// and a file can be created in their folder (tried with a temporary, removed at once).
void checkOutputsWritable(const std::filesystem::path& out) {
  std::error_code ec;
  if (out.filename().empty()) throw SettingsError("output " + out.string() + ": names a folder, not a file stem");
  for (const char* e : {".exr", ".png", ".json"}) {
    const std::filesystem::path p = out.string() + e;
    if (std::filesystem::is_directory(p, ec)) throw SettingsError("cannot write " + p.string() + ": it is a directory");
  }
  const std::filesystem::path folder = out.parent_path().empty() ? std::filesystem::path(".") : out.parent_path();
  const std::filesystem::path probe = folder / (".voxcone-probe-" + std::to_string(::getpid()));
  FILE* f = std::fopen(probe.c_str(), "wb");
  if (!f) throw SettingsError("cannot write into " + folder.string() + ": " + std::strerror(errno));
  std::fclose(f);
  std::filesystem::remove(probe, ec);
}

/// The scene a render reads, with what its sidecar records of it.
struct LoadedScene {
  Scene scene;
  std::string name;       ///< the file's stem, or the built-in scene's name
  double seconds = 0.0;   ///< reading it
  nlohmann::json inputs;  ///< sidecarInputs
};

/// The scene of `o` (the built-in cornell-box where none is given), its input files hashed as
/// they were read.
LoadedScene loadRenderScene(const RenderOptions& o) {
  Timer t;
  if (o.scenePath.empty() && !o.defines.empty())
    throw SettingsError("-D sets parameters of a Mitsuba XML scene; none is given");
  LoadedScene s{o.scenePath.empty() ? parseScene(kDefaultSceneJson, "cornell-box (built-in)", ".")
                                    : loadScene(o.scenePath, parseDefines(o.defines)),
                o.scenePath.empty() ? std::string(kDefaultSceneName) : std::filesystem::path(o.scenePath).stem().string(),
                0.0, nullptr};
  s.seconds = t.seconds();
  // What the image was made from, hashed as it was read (xxhsum -H2 checks a file against it).
  s.inputs = sidecarInputs(s.scene.inputFiles);
  return s;
}

/// Whether `o` asks for a progressive render (--target-error or --time-budget).
bool isProgressive(const RenderOptions& o) { return o.targetError > 0.0 || o.timeBudget > 0.0; }

/// The scene's render settings with `o`'s overrides, validated; the light sampler's options
/// set on the scene as well.
RenderSettings renderSettings(const RenderOptions& o, Scene& scene) {
  RenderSettings settings = scene.render;
  if (isProgressive(o)) {
    if (!o.method.empty() && o.method != "voxcone")
      throw SettingsError("--target-error and --time-budget choose voxcone's settings; --method " + o.method +
                          " has none to choose");
    settings.method = "voxcone";
  }
  if (!o.method.empty()) settings.method = o.method;
  if (o.spp != 0) settings.spp = o.spp;
  if (!o.resolution.empty()) parseResolution(o.resolution, settings);
  if (o.seed) settings.seed = *o.seed;
  if (o.maxDepth != 0) settings.maxDepth = o.maxDepth;
  if (!o.sampler.empty()) settings.sampler = samplerKindFromName(o.sampler);
  if (!o.lightSampler.empty()) {
    settings.lightTree = o.lightSampler == "tree";
    scene.setLightTree(settings.lightTree);
  }
  if (o.lightSplit) {
    settings.lightSplitDeg = *o.lightSplit;
    scene.setLightSplit(settings.lightSplitDeg);
  }
  settings.validate();
  return settings;
}

/// --denoise: the denoiser, and the AOV layers rendered only for it (not written).
struct DenoiseSetup {
  std::optional<LoadedDenoiser> denoiser;
  std::vector<Aov> onlyLayers;
};

/// The AOV layers `o` asks for, and with --denoise the first hit's albedo and normal the
/// network takes (written only where --aov asks for them). The denoiser's weights are read
/// here, before any work is done; `settings` records the denoising.
AovRequest aovRequest(const RenderOptions& o, RenderSettings& settings, DenoiseSetup& denoise) {
  AovRequest aovs;
  if (!o.aovs.empty()) {
    aovs.layers = parseAovs(o.aovs);
    if (isProgressive(o)) throw SettingsError("--aov with --target-error / --time-budget: the passes are averaged images, not layers");
  }
  if (o.denoise) {
    if (isProgressive(o)) throw SettingsError("--denoise with --target-error / --time-budget is not supported");
    denoise.denoiser = loadDenoiser(true, true, o.denoiseWeights);
    settings.denoise = true;
    for (Aov a : {Aov::Albedo, Aov::Normal})
      if (std::find(aovs.layers.begin(), aovs.layers.end(), a) == aovs.layers.end()) {
        aovs.layers.push_back(a);
        denoise.onlyLayers.push_back(a);
      }
  } else if (!o.denoiseWeights.empty()) {
    throw SettingsError("--denoise-weights without --denoise");
  }
  return aovs;
}

/// The integrator's options: --options, with --field and --memory-budget-mb (voxcone options,
/// voxel_cone.h, with a flag of their own).
nlohmann::json integratorOptions(const RenderOptions& o, const RenderSettings& settings) {
  nlohmann::json options;
  try {
    options = nlohmann::json::parse(o.integratorOptions);
  } catch (const nlohmann::json::parse_error&) {
    throw SettingsError("--options is not valid JSON: " + o.integratorOptions);
  }
  for (const auto& [flag, key, given] :
       {std::tuple<const char*, const char*, bool>{"--field", "field", !o.field.empty()},
        {"--memory-budget-mb", "memory_budget_mb", o.memoryBudgetMb >= 0.0}}) {
    if (!given) continue;
    if (settings.method != "voxcone") throw SettingsError(std::string(flag) + " is a voxcone option; --method is " + settings.method);
    if (options.is_object() && options.contains(key))
      throw SettingsError(std::string(flag) + " and --options' \"" + key + "\" both given");
  }
  if (!o.field.empty()) {
    if (isProgressive(o))
      throw SettingsError("--field renders with the field's photons; --target-error and --time-budget trace new photons "
                          "for every pass");
    if (!std::filesystem::is_regular_file(o.field)) throw SettingsError("--field: no such file: " + o.field);
    options["field"] = o.field;
  }
  if (o.memoryBudgetMb >= 0.0) options["memory_budget_mb"] = o.memoryBudgetMb;
  return options;
}

/// The output stem: <stem>.exr, <stem>.png and <stem>.json are written next to each other.
/// Throws SettingsError where they could not all be written, or one would replace the scene.
std::filesystem::path outputStem(const RenderOptions& o, const std::string& sceneName) {
  std::filesystem::path out = o.output.empty() ? std::filesystem::path("out") / sceneName : std::filesystem::path(o.output);
  const std::string ext = out.extension().string();
  if (ext == ".exr" || ext == ".png" || ext == ".json") out.replace_extension();
  else if (!o.output.empty() && !ext.empty())
    throw SettingsError("-o " + o.output + ": unknown extension '" + ext +
                        "'; voxcone writes STEM.exr, STEM.png and STEM.json: give STEM or STEM.exr");
  if (o.output.empty()) std::filesystem::create_directories(out.parent_path());
  else if (!out.parent_path().empty() && !std::filesystem::is_directory(out.parent_path()))
    throw SettingsError("output folder does not exist: " + out.parent_path().string());

  // Never let an output replace the scene file (e.g. -o scene writes scene.json).
  if (!o.scenePath.empty())
    for (const char* e : {".exr", ".png", ".json"}) {
      std::error_code ec;
      if (std::filesystem::equivalent(out.string() + e, o.scenePath, ec))
        throw SettingsError("output " + out.string() + e + " would overwrite the scene file");
    }
  // Every output writable before any work is done (a read-only folder, a directory where a
  // file goes: found after the render, they left part of the set behind or wasted it).
  checkOutputsWritable(out);
  return out;
}

/// A render's image and what made it.
struct RenderRun {
  std::unique_ptr<Integrator> integrator;
  RenderResult result;
  double pilotSeconds = 0.0, prepareSeconds = 0.0;
  nlohmann::json progressiveReport;  ///< null where not progressive
};

/// --target-error / --time-budget: voxcone in averaged passes until the predicted error meets
/// the target or the budget is spent (progressive.h). `settings.spp` becomes the passes'.
RenderRun renderProgressively(const RenderOptions& o, const Scene& scene, const Accel& accel, RenderSettings& settings,
                              const nlohmann::json& options, const Timer& total, Progress& progress) {
  ProgressiveRequest request;
  request.targetRelMse = o.targetError;
  request.timeBudget = o.timeBudget > 0.0 ? std::max(1e-3, o.timeBudget - total.seconds()) : 0.0;
  request.options = options;
  if (o.spp != 0) request.passSpp = o.spp;
  ProgressiveResult chosen = renderVoxconeToTarget(scene, accel, settings, request, &progress);
  settings.spp = chosen.passes * request.passSpp;
  RenderRun run;
  run.pilotSeconds = chosen.controlSeconds;
  run.prepareSeconds = chosen.prepareSeconds;
  run.progressiveReport = chosen.report;
  run.integrator = std::move(chosen.integrator);
  run.result = std::move(chosen.result);
  if (!o.quiet) {
    std::printf("%s", chosen.summary.c_str());
    std::fflush(stdout);
  }
  return run;
}

/// The integrator of `settings.method`, prepared, and its image.
RenderRun renderOnce(const RenderOptions& o, const Scene& scene, const Accel& accel, const RenderSettings& settings,
                     const nlohmann::json& options, const AovRequest& aovs, Progress& progress) {
  RenderRun run;
  IntegratorContext ctx{scene, accel, settings, options};
  run.integrator = createIntegrator(settings.method, ctx);
  // Term layers need an integrator that separates them: known before anything is traced.
  checkAovs(*run.integrator, aovs.layers);
  Timer t;
  run.integrator->prepare(&progress);
  run.prepareSeconds = t.seconds();
  run.result = renderImage(scene, *run.integrator, settings, &progress, o.writePartial, &aovs);
  return run;
}

/// The image through the denoiser, with the albedo and normal layers it takes; the layers
/// rendered only for it removed. Its report for the sidecar.
nlohmann::json denoiseImage(const DenoiseSetup& denoise, const RenderSettings& settings, RenderResult& result) {
  Timer td;
  const auto layerImage = [&](Aov a) {
    for (const ImageLayer& l : result.layers)
      if (l.name == aovNames()[size_t(a)]) {
        Image img(settings.width, settings.height);
        for (size_t p = 0; p < img.pixels.size(); ++p)
          for (int k = 0; k < 3; ++k) img.pixels[p][k] = l.values[p * 3 + size_t(k)];
        return img;
      }
    throw Error("--denoise: the render has no " + aovNames()[size_t(a)] + " layer");
  };
  const Image albedo = layerImage(Aov::Albedo), normal = layerImage(Aov::Normal);
  DenoiseTimings tm;
  result.image = denoise.denoiser->denoiser.denoise(result.image, &albedo, &normal, &tm);
  for (Aov a : denoise.onlyLayers)
    result.layers.erase(std::remove_if(result.layers.begin(), result.layers.end(),
                                       [&](const ImageLayer& l) { return l.name == aovNames()[size_t(a)]; }),
                        result.layers.end());
  return {{"weights", std::filesystem::path(denoise.denoiser->weightsPath).filename().string()},
          {"seconds", td.seconds()}, {"input_seconds", tm.input}, {"network_seconds", tm.network},
          {"output_seconds", tm.output}};
}

/// Write <out>.exr, <out>.png and the sidecar <out>.json as a set (OutputSet): the EXR and the
/// PNG to temporaries side by side (5 and 6.5 ms at 256x256, one after the other 11.5 ms of a
/// 0.13 s render), then renamed together, the sidecar last (it marks a set complete: batch
/// --skip-existing). Any failure leaves none of them. The sidecar gets the writing's record.
void writeOutputs(const std::filesystem::path& out, const RenderResult& result, nlohmann::json& sidecar,
                  const Timer& total) {
  const std::string exrPath = out.string() + ".exr", pngPath = out.string() + ".png", jsonPath = out.string() + ".json";
  OutputSet files;
  Timer t;
  double exrSec = 0.0;
  std::exception_ptr exrError, pngError;
  tbb::task_group writes;
  writes.run([&] {
    try {
      Timer te;
      writeExr(exrPath, result.image, sidecar, &files, result.layers);
      exrSec = te.seconds();
    } catch (...) {
      exrError = std::current_exception();
    }
  });
  writes.run_and_wait([&] {
    try {
      writePng(pngPath, result.image, &files, sidecar);
    } catch (...) {
      pngError = std::current_exception();
    }
  });
  if (exrError || pngError) std::rethrow_exception(exrError ? exrError : pngError);
  addWrittenOutputs(sidecar, t.seconds(), exrSec, total.seconds(), exrPath, pngPath);
  writeJsonAtomic(jsonPath, sidecar, &files);
  files.commit(jsonPath);
  std::printf("wrote %s (%s, %s)%s\n", exrPath.c_str(), pngPath.c_str(), jsonPath.c_str(),
              result.partial ? ", partial" : "");
}

/// Throws NotMetError where a progressive render's target or budget was not met (its image is
/// written).
void checkProgressiveMet(const RenderOptions& o, const nlohmann::json& report, const Timer& total) {
  if (report.value("met", true)) return;
  char what[256];
  if (o.targetError > 0.0)
    std::snprintf(what, sizeof what, "--target-error %.4g: predicted relMSE %.4g after %d passes (%s); the image is written",
                  o.targetError, report.value("predicted_relmse", 0.0), report["chosen"].value("passes", 0),
                  report.value("stopped_by", std::string()).c_str());
  else
    std::snprintf(what, sizeof what, "--time-budget %.3g s: took %.3g s for the 2 passes a prediction needs; the image is written",
                  o.timeBudget, total.seconds());
  throw NotMetError(what);
}

void runRender(const RenderOptions& o) {
  Timer total;
  ThreadLimit threads(o.threads);
  ConsoleProgress progress(o.quiet);

  // Parse and check everything before any work is done.
  LoadedScene loaded = loadRenderScene(o);
  Scene& scene = loaded.scene;
  RenderSettings settings = renderSettings(o, scene);
  DenoiseSetup denoise;
  AovRequest aovs = aovRequest(o, settings, denoise);
  const nlohmann::json options = integratorOptions(o, settings);
  const std::filesystem::path out = outputStem(o, loaded.name);

  Timer t;
  const std::unique_ptr<Accel> accel = buildAccel(o.accel, scene, &progress);
  const double buildSec = t.seconds();
  aovs.accel = accel.get();

  RenderRun run = isProgressive(o) ? renderProgressively(o, scene, *accel, settings, options, total, progress)
                                   : renderOnce(o, scene, *accel, settings, options, aovs, progress);
  RenderResult& result = run.result;
  const nlohmann::json denoiseReport = denoise.denoiser ? denoiseImage(denoise, settings, result) : nlohmann::json();
  // Interrupted with --write-partial: the image holds the passes that completed, written as a
  // complete set that says so (sidecar "partial", EXR voxcone:partial, spp the samples taken).
  const int requestedSpp = settings.spp;
  if (result.partial) settings.spp = result.completedSpp;

  RenderRecord record;
  record.version = kVersion;
  record.scene = o.scenePath.empty() ? std::string("built-in:") + kDefaultSceneName
                                     : std::filesystem::absolute(o.scenePath).lexically_normal().string();
  record.commandLine = commandLine();
  record.executable = selfExe();
  record.workingDirectory = std::filesystem::current_path().string();
  record.inputs = loaded.inputs;
  record.threads = threads.threads();
  record.sceneData = &scene;
  record.accel = accel.get();
  record.integrator = run.integrator.get();
  record.settings = settings;
  record.requestedSpp = requestedSpp;
  record.result = &result;
  record.timings = {loaded.seconds, buildSec, run.pilotSeconds, run.prepareSeconds};
  record.progressiveReport = run.progressiveReport;
  record.denoiseReport = denoiseReport;
  nlohmann::json sidecar = renderSidecar(record);
  writeOutputs(out, result, sidecar, total);

  if (result.partial) {
    char what[512];
    std::snprintf(what, sizeof what, "wrote a partial image of %d of %d spp to %s", settings.spp, requestedSpp,
                  (out.string() + ".exr").c_str());
    throw CancelledError(what);
  }
  std::printf("%s: %dx%d, %d spp, %s, render %.2f s, total %.2f s\n", settings.method.c_str(), settings.width,
              settings.height, settings.spp, loaded.name.c_str(), result.seconds, total.seconds());
  if (isProgressive(o)) checkProgressiveMet(o, run.progressiveReport, total);
}

}  // namespace

void addRenderCommand(CLI::App& app) {
  auto o = std::make_shared<RenderOptions>();
  CLI::App* cmd = app.add_subcommand("render", "Render a scene to EXR, PNG and a JSON sidecar");
  cmd->add_option("scene", o->scenePath, "Scene file (JSON, Mitsuba 3 XML: .xml, or glTF 2.0: .gltf, .glb)")->default_str("the built-in cornell-box");
  addDefineOption(*cmd, o->defines);
  cmd->add_option("-o,--output", o->output, "Output stem (or STEM.exr/.png/.json): STEM.exr, STEM.png and STEM.json are written; any other extension is an error")
      ->check(nonEmpty())
      ->default_str("out/<scene>");
  cmd->add_option("--method", o->method, "Integrator: " + [] {
    std::string s;
    for (const auto& n : integratorNames()) s += (s.empty() ? "" : "|") + n;
    return s;
  }())->check(nonEmpty())->default_str("the scene's");
  cmd->add_option("--spp", o->spp, "Samples per pixel")->check(CLI::Range(1, 1 << 24))->default_str("the scene's");
  cmd->add_option("--res", o->resolution, "Resolution WIDTHxHEIGHT")->default_str("the scene's");
  cmd->add_option_function<std::string>(
      "--seed", [o](const std::string& s) { o->seed = parseSeed("--seed", s); }, "Random seed, [0, 2^64 - 1]")->default_str("the scene's");
  cmd->add_option("--sampler", o->sampler, "Pixel sampler: sobol (Owen-scrambled) or independent")
      ->check(CLI::IsMember(samplerNames()))
      ->default_str("the scene's, else sobol");
  cmd->add_option("--light-sampler", o->lightSampler,
                  "How a shading point chooses among the bounded lights: tree (by estimated contribution) or power")
      ->check(CLI::IsMember({"tree", "power"}))
      ->default_str("the scene's, else tree");
  cmd->add_option("--light-split", o->lightSplit,
                  "The light tree's split angle, degrees: a node seen wider than it (or from inside) gives a light "
                  "sample from each child (0: one light per sample)")
      ->check(CLI::Range(0.0f, 90.0f))
      ->default_str("the scene's, else " + std::to_string(int(RenderSettings().lightSplitDeg)));
  cmd->add_option("-t,--threads", o->threads, "Threads (0 = all)")->check(CLI::Range(0, 4096));
  cmd->add_option("--max-depth", o->maxDepth, "Maximum path length / recursion depth")->check(CLI::Range(1, 1024))->default_str("the scene's");
  cmd->add_option("--options", o->integratorOptions, "Integrator options as a JSON object");
  cmd->add_option("--accel", o->accel, "Ray acceleration structure: hbvh, bvh (no spheres), kdtree, or embree where built with it")
      ->check(CLI::IsMember(accelKinds()));
  cmd->add_option("--target-error", o->targetError,
                  "voxcone: render averaged passes (of --spp, default 4) until the predicted relMSE against the true "
                  "image, from the passes' spread and path-traced control pixels, is at most this")
      ->check(positiveNumber())
      ->default_str("off");
  cmd->add_option("--time-budget", o->timeBudget,
                  "voxcone: render averaged passes (of --spp, default 4) for this many seconds (load included)")
      ->check(positiveNumber())
      ->default_str("off");
  cmd->add_option("--field", o->field,
                  "voxcone: render with this field (.vdb from 'voxcone voxelize -o') instead of tracing photons and "
                  "voxelizing; its levels and photons are the field's")
      ->check(nonEmpty());
  cmd->add_option("--memory-budget-mb", o->memoryBudgetMb,
                  "voxcone: refuse a voxel level whose estimated memory exceeds this many MB, before allocating (0: no "
                  "budget)")
      ->check(CLI::Range(0.0, 1e12))
      ->default_str("the machine's available memory");
  cmd->add_flag("--write-partial", o->writePartial,
                "On SIGINT/SIGTERM write the samples taken so far (whole passes of every pixel) as a complete "
                "image marked partial, with its spp; the exit status still says interrupted (128 + the signal). "
                "Not for voxcone, whose samples are one pass")
      ->default_str("");
  cmd->add_option("--aov", o->aovs,
                  "Layers written into the EXR beside RGB, comma-separated: albedo (Albedo.RGB), normal (Ns.XYZ), "
                  "depth (Z): the first hit, box-filtered; emitted, direct, indirect, caustic (Emitted.RGB ...): "
                  "the radiance's terms, which add up to RGB (path, whitted, voxcone)")
      ->default_str("none");
  cmd->add_flag("--denoise", o->denoise,
                "Denoise the image with Open Image Denoise's RT network, with the first hit's albedo and normal "
                "(weights: bash tools/fetch_models.sh)");
  cmd->add_option("--denoise-weights", o->denoiseWeights, "Folder of the denoiser's .tza weights")
      ->default_str("data/models/oidn");
  cmd->add_flag("-q,--quiet", o->quiet, "No progress output");
  cmd->callback([o] { runRender(*o); });
}

}  // namespace voxcone

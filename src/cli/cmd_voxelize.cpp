// `voxcone voxelize SCENE --level L`: trace photons, voxelize, inject, build the mips, print a
// table per grid and level, and write every grid into one .vdb file.

#include "cli_util.h"
#include "commands.h"
#include "voxcone/accel/hbvh.h"
#include "voxcone/core/error.h"
#include "voxcone/core/parallel.h"
#include "voxcone/core/timer.h"
#include "voxcone/photon/photon_tracer.h"
#include "voxcone/scene/scene.h"
#include "voxcone/voxel/voxel_field.h"

#include <nlohmann/json.hpp>

#include <cstdio>
#include <filesystem>

namespace voxcone {

namespace {

struct VoxelizeOptions {
  std::string scenePath;
  std::vector<std::string> defines;  // -D NAME=VALUE: Mitsuba scene parameters
  std::string output;
  int level = 8;
  int coarsest = 2;
  int causticLevel = -1;  // -1: level + 1 when the scene has specular surfaces, else none
  int64_t photons = -1;    // -1: the scene's render.photons
  int64_t causticPhotons = -1;
  uint64_t seed = 0;
  int threads = 0;
  bool json = false;
  bool quiet = false;
  double memoryBudgetMb = -1.0;  // -1: the available memory; 0: no budget
  bool measureQuantization = false;
};

void runVoxelize(const VoxelizeOptions& o) {
  Timer total;
  ThreadLimit threads(o.threads);
  ConsoleProgress progress(o.quiet || o.json);
  if (o.coarsest > o.level) throw SettingsError("--coarsest-level must not exceed --level");
  if (o.causticLevel > 0 && (o.causticLevel < o.level || o.causticLevel > 13))
    throw SettingsError("--caustic-level must be 0 or in [level, 13]");

  // The peak resident set after each stage (the process's high-water mark so far).
  nlohmann::json peakAfter;
  Timer t;
  const Scene scene = loadScene(o.scenePath, parseDefines(o.defines));
  const double loadSec = t.seconds();
  peakAfter["load"] = peakRssBytes();
  t.reset();
  const Hbvh accel(scene, HbvhBuildSettings{}, &progress);
  const double buildSec = t.seconds();
  peakAfter["hbvh"] = peakRssBytes();

  // Model no more than the scene needs: a caustic grid only where a specular surface can focus
  // light (L S+ D paths need a delta material). By default one level finer than the field, at
  // most level 10 (0.55 mm voxels in the Cornell box); it holds only the voxels the caustic
  // photons reach (VoxelField::build, as a render's field).
  bool specular = false;
  for (const Material& m : scene.materials) specular = specular || m.hasDeltaLobe();
  const int causticLevel =
      o.causticLevel >= 0 ? o.causticLevel : (specular ? std::max(o.level, std::min(o.level + 1, 10)) : 0);

  PhotonSettings ps;
  uint64_t photons, causticPhotons;
  defaultPhotonCounts(scene.render.photons, scene.render.causticPhotons, kVoxconeDefaultPhotons, kVoxconeDefaultCausticPhotons, photons,
                      causticPhotons);
  ps.photons = o.photons >= 0 ? uint64_t(o.photons) : photons;
  ps.causticPhotons = causticLevel > 0 ? (o.causticPhotons >= 0 ? uint64_t(o.causticPhotons) : causticPhotons) : 0;
  ps.seed = o.seed;
  const PhotonMaps maps = tracePhotons(scene, accel, ps, &progress);
  peakAfter["photons"] = peakRssBytes();

  VoxelSettings vs;
  vs.level = o.level;
  vs.coarsestLevel = o.coarsest;
  vs.causticLevel = causticLevel;
  vs.memoryBudgetBytes = VoxelSettings::budgetFromMegabytes(o.memoryBudgetMb);
  vs.measureQuantization = o.measureQuantization;
  // The estimate the budget is checked against, beside what the field turns out to take.
  const std::vector<FieldEstimate> estimates = VoxelField::estimate(scene, vs);
  VoxelField::BuildStats built;
  VoxelField field = VoxelField::build(scene, vs, maps, maps, &progress, &built);
  peakAfter["voxelize"] = built.peakAfterVoxelize;
  peakAfter["inject"] = built.peakAfterInject;
  peakAfter["mips"] = built.peakAfterMips;
  const double voxelizeSec = built.voxelizeSeconds, injectSec = built.injectSeconds, mipSec = built.mipsSeconds;

  nlohmann::json j;
  j["scene"] = o.scenePath;
  j["level"] = o.level;
  j["coarsest_level"] = o.coarsest;
  j["caustic_level"] = causticLevel;
  j["voxel_size"] = field.voxelSize(o.level);
  j["photons"] = maps.stats.toJson();
  j["timings"] = {{"load_seconds", loadSec},         {"hbvh_seconds", buildSec},
                  {"photon_seconds", maps.stats.seconds}, {"voxelize_seconds", voxelizeSec},
                  {"inject_seconds", injectSec},     {"mip_seconds", mipSec}};
  nlohmann::json rows = nlohmann::json::array();
  for (const VoxelGridStats& g : field.stats())
    rows.push_back({{"grid", g.grid}, {"level", g.level}, {"voxel_size", g.voxelSize}, {"active_voxels", g.activeVoxels},
                    {"leaves", g.leaves}, {"bytes", g.bytes},
                    {"bytes_per_voxel", g.activeVoxels > 0 ? double(g.bytes) / double(g.activeVoxels) : 0.0},
                    {"seconds", g.seconds}});
  j["grids"] = rows;
  const FieldEstimate& est = estimates.back();
  j["estimate"] = {{"voxels", est.voxels}, {"field_bytes", est.fieldBytes}, {"peak_bytes", est.peakBytes},
                   {"probe_level", est.probeLevel}};
  j["total_bytes"] = field.memoryBytes();
  if (o.measureQuantization) j["quantization"] = field.quantizationJson();

  if (!o.output.empty()) {
    t.reset();
    field.write(o.output, j);
    j["timings"]["write_seconds"] = t.seconds();
    peakAfter["write"] = peakRssBytes();
    j["output"] = o.output;
  }
  j["timings"]["total_seconds"] = total.seconds();
  j["peak_rss_bytes"] = peakRssBytes();
  j["peak_rss_bytes_after"] = peakAfter;

  if (o.json) {
    std::printf("%s\n", j.dump(2).c_str());
    return;
  }
  std::printf("%-10s %5s %10s %12s %10s %12s %9s\n", "grid", "level", "voxel", "active", "leaves", "bytes", "seconds");
  for (const VoxelGridStats& g : field.stats())
    std::printf("%-10s %5d %10.4g %12llu %10llu %12llu %9.3f\n", g.grid.c_str(), g.level, g.voxelSize,
                (unsigned long long)g.activeVoxels, (unsigned long long)g.leaves, (unsigned long long)g.bytes, g.seconds);
  std::printf("total      %.2f MiB in memory; photons %llu global + %llu caustic stored (%.2f s); voxelize %.2f s, "
              "inject %.2f s, mips %.2f s; peak RSS %.1f MiB\n",
              double(field.memoryBytes()) / (1024.0 * 1024.0), (unsigned long long)maps.stats.storedGlobal,
              (unsigned long long)maps.stats.storedCaustic, maps.stats.seconds, voxelizeSec, injectSec, mipSec,
              double(peakRssBytes()) / (1024.0 * 1024.0));
  if (o.measureQuantization) {
    const nlohmann::json q = field.quantizationJson();
    std::printf("quantization: coverage %.2g (max %.2g) relative, normal %.2f (max %.2f) degrees, radiance %.2g (max "
                "%.2g) relative, axes %.2g (max %.2g), diffuse %.2g (max %.2g)\n",
                q["coverage_relative"]["mean"].get<double>(), q["coverage_relative"]["max"].get<double>(),
                q["normal_degrees"]["mean"].get<double>(), q["normal_degrees"]["max"].get<double>(),
                q["radiance_relative"]["mean"].get<double>(), q["radiance_relative"]["max"].get<double>(),
                q["axes_absolute"]["mean"].get<double>(), q["axes_absolute"]["max"].get<double>(),
                q["diffuse_absolute"]["mean"].get<double>(), q["diffuse_absolute"]["max"].get<double>());
  }
  if (!o.output.empty()) std::printf("wrote %s\n", o.output.c_str());
}

}  // namespace

void addVoxelizeCommand(CLI::App& app) {
  auto o = std::make_shared<VoxelizeOptions>();
  CLI::App* cmd = app.add_subcommand("voxelize", "Trace photons, voxelize into OpenVDB grids with mips, write a .vdb");
  cmd->add_option("scene", o->scenePath, "Scene file (JSON, Mitsuba 3 XML: .xml, or glTF 2.0: .gltf, .glb)")->required();
  addDefineOption(*cmd, o->defines);
  cmd->add_option("--level", o->level, "Finest level: 2^L voxels across the longest axis")->check(CLI::Range(1, 13));
  cmd->add_option("--coarsest-level", o->coarsest, "Coarsest mip level built")->check(CLI::Range(0, 13));
  cmd->add_option("--caustic-level", o->causticLevel,
                  "Level of the caustic grid (0: none; default: when the scene has specular surfaces, level + 1 "
                  "up to 10, never below level)")
      ->check(CLI::Range(0, 13))
      ->default_str("level + 1 up to 10 with specular surfaces, else 0");
  cmd->add_option("--photons", o->photons, "Photons emitted for the global map")
      ->check(CLI::Range(int64_t(0), int64_t(1) << 36))
      ->default_str("the scene's render.photons");
  cmd->add_option("--caustic-photons", o->causticPhotons, "Photons emitted for the caustic map")
      ->check(CLI::Range(int64_t(0), int64_t(1) << 36))
      ->default_str("the scene's");
  cmd->add_option("--seed", o->seed, "Random seed");
  cmd->add_option("-o,--output", o->output, "Write all grids and levels to this .vdb file");
  cmd->add_option("-t,--threads", o->threads, "Threads (0 = all)")->check(CLI::Range(0, 4096));
  cmd->add_option("--memory-budget-mb", o->memoryBudgetMb,
                  "Refuse a level whose estimated memory exceeds this many MB, before allocating (0: no budget; "
                  "default: the machine's available memory)")
      ->check(CLI::Range(0.0, 1e12))
      ->default_str("the machine's available memory");
  cmd->add_flag("--measure-quantization", o->measureQuantization,
                "Measure the error each compact encoding adds (in the --json output and the table's last line; "
                "slows voxelizing a little)");
  cmd->add_flag("--json", o->json, "Print the table as JSON on stdout");
  cmd->add_flag("-q,--quiet", o->quiet, "No progress output");
  cmd->callback([o] { runVoxelize(*o); });
}

}  // namespace voxcone

// `voxcone convert IN -o OUT`: Mitsuba 3 XML <-> voxcone JSON, by the output's extension.

#include "cli_util.h"
#include "commands.h"
#include "voxcone/core/error.h"
#include "voxcone/scene/mitsuba.h"

#include <filesystem>

namespace voxcone {

void addConvertCommand(CLI::App& app) {
  struct Opts {
    std::string in, out;
    std::vector<std::string> defines;
  };
  auto o = std::make_shared<Opts>();
  CLI::App* cmd = app.add_subcommand(
      "convert", "Convert a scene between Mitsuba 3 XML and voxcone JSON (by OUT's extension, .xml or .json); the "
                 "meshes go to binary PLY files in OUT_STEM_meshes/");
  cmd->add_option("scene", o->in, "Scene file (JSON or Mitsuba XML)")->required();
  cmd->add_option("-o,--output", o->out, "Output scene: .xml (Mitsuba 3) or .json (voxcone)")->required()->check(nonEmpty());
  addDefineOption(*cmd, o->defines);
  cmd->callback([o] {
    namespace fs = std::filesystem;
    const std::string ext = fs::path(o->out).extension().string();
    if (ext != ".xml" && ext != ".json") throw SettingsError("convert: -o must end in .xml or .json, got " + o->out);
    std::error_code ec;
    if (fs::equivalent(o->in, o->out, ec)) throw SettingsError("convert: the output would overwrite the input " + o->in);
    const fs::path folder = fs::path(o->out).parent_path();
    if (!folder.empty() && !fs::is_directory(folder)) throw SettingsError("output folder does not exist: " + folder.string());
    const Scene scene = loadScene(o->in, parseDefines(o->defines));
    if (ext == ".xml") writeMitsubaScene(scene, o->out);
    else writeJsonScene(scene, o->out);
    std::printf("wrote %s\n", o->out.c_str());
  });
}

}  // namespace voxcone

// `voxcone generate-mesh --triangles N -o FILE.ply`: a knot mesh of about N triangles for the
// structures and scaling studies (generate.h).

#include "commands.h"
#include "voxcone/core/error.h"
#include "voxcone/core/timer.h"
#include "voxcone/scene/generate.h"

#include <filesystem>

namespace voxcone {

void addGenerateCommand(CLI::App& app) {
  struct Options {
    uint64_t triangles = 0;
    std::string output;
  };
  auto o = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand("generate-mesh", "Write a generated knot mesh of about N triangles (binary PLY)");
  cmd->add_option("--triangles", o->triangles, "Triangle count (the nearest the knot's grid allows)")->required();
  cmd->add_option("-o,--output", o->output, "Output file (.ply)")->required();
  cmd->callback([o] {
    if (std::filesystem::path(o->output).extension() != ".ply")
      throw SettingsError("generate-mesh writes PLY: the output must end in .ply, got " + o->output);
    Timer t;
    const TriangleMesh mesh = makeKnotMesh(o->triangles);
    writePly(o->output, mesh);
    std::printf("wrote %s: %zu triangles, %zu vertices (%.2f s)\n", o->output.c_str(), mesh.triangles.size(),
                mesh.positions.size(), t.seconds());
  });
}

}  // namespace voxcone

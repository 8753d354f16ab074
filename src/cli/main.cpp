// voxcone: the command-line front end. Library errors become one line on stderr and exit 2.

#include "commands.h"
#include "voxcone/core/error.h"
#include "voxcone/core/progress.h"

#include <cstdio>
#include <exception>

int main(int argc, char** argv) {
  CLI::App app{"voxcone: physically based rendering with exact hits and voxel cone gathering"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "voxcone 0.1.0");
  voxcone::addRenderCommand(app);
  voxcone::addCompareCommand(app);
  voxcone::addInfoCommand(app);
  voxcone::addVoxelizeCommand(app);
  voxcone::addStudyCommand(app);
  voxcone::addBatchCommand(app);
  voxcone::addGenerateCommand(app);
  voxcone::installInterruptHandler();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const voxcone::NotMetError& e) {
    std::fprintf(stderr, "voxcone: not met: %s\n", e.what());
    return 3;
  } catch (const voxcone::CancelledError&) {
    std::fprintf(stderr, "voxcone: interrupted; no output written\n");
    return 130;
  } catch (const voxcone::Error& e) {
    std::fprintf(stderr, "voxcone: error: %s\n", e.what());
    return 2;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "voxcone: error: out of memory\n");
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "voxcone: error: %s\n", e.what());
    return 2;
  }
  return 0;
}

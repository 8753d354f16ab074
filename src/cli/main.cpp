// voxcone: the command-line front end. Usage and library errors become one line on stderr and
// exit 2.

#include "cli_util.h"
#include "commands.h"
#include "version.h"
#include "voxcone/core/error.h"
#include "voxcone/core/progress.h"

#include <cstdio>
#include <string>
#include <exception>

namespace {

/// One printable line: control characters and bytes that are not valid UTF-8 (a binary file's
/// bytes echoed by a parser) become '?', line breaks and tabs spaces; UTF-8 (file names) stays.
std::string printable(const char* what) {
  std::string out;
  const auto* p = reinterpret_cast<const unsigned char*>(what);
  while (*p) {
    const unsigned char c = *p;
    if (c < 0x80) {
      out += c == '\n' || c == '\r' || c == '\t' ? ' ' : c < 32 || c == 127 ? '?' : char(c);
      ++p;
      continue;
    }
    const int len = (c >> 5) == 0x6 ? 2 : (c >> 4) == 0xe ? 3 : (c >> 3) == 0x1e ? 4 : 0;
    bool ok = len > 0;
    for (int k = 1; ok && k < len; ++k) ok = (p[k] & 0xc0) == 0x80;
    if (ok) {
      out.append(reinterpret_cast<const char*>(p), size_t(len));
      p += len;
    } else {
      out += '?';
      ++p;
    }
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"voxcone: physically based rendering with exact hits and voxel cone gathering"};
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string("voxcone ") + voxcone::kVersion + " (" + voxcone::kBuildType + ")");
  // Every option's help shows its default (subcommands inherit this); options whose default
  // is another source's value (the scene's spp, say) name that source instead.
  app.option_defaults()->always_capture_default();
  voxcone::addRenderCommand(app);
  voxcone::addCompareCommand(app);
  voxcone::addInfoCommand(app);
  voxcone::addVoxelizeCommand(app);
  voxcone::addStudyCommand(app);
  voxcone::addBatchCommand(app);
  voxcone::addGenerateCommand(app);
  voxcone::addConvertCommand(app);
  voxcone::addDenoiseCommand(app);
  voxcone::installInterruptHandler();
  voxcone::setCommandLine(argc, argv);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help and --version print and succeed; every usage error is one line and exit 2 like
    // any other bad input (CLI11's own codes, 105-114, said nothing a script could use).
    if (e.get_exit_code() == 0) return app.exit(e);
    // A command's own verdict (batch: a job failed; compare: over a threshold), already said.
    if (dynamic_cast<const CLI::RuntimeError*>(&e)) return e.get_exit_code();
    std::fprintf(stderr, "voxcone: usage error: %s (see voxcone --help)\n", printable(e.what()).c_str());
    return 2;
  } catch (const voxcone::NotMetError& e) {
    std::fprintf(stderr, "voxcone: not met: %s\n", printable(e.what()).c_str());
    return 3;
  } catch (const voxcone::CancelledError& e) {
    // 128 + the signal, as a shell reports a process it killed: schedulers and batch read it.
    const std::string what = e.what();
    std::fprintf(stderr, "voxcone: interrupted; %s\n", what == "cancelled" ? "no output written" : printable(e.what()).c_str());
    return voxcone::interruptedExitCode();
  } catch (const voxcone::Error& e) {
    std::fprintf(stderr, "voxcone: error: %s\n", printable(e.what()).c_str());
    return 2;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "voxcone: error: out of memory\n");
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "voxcone: error: %s\n", printable(e.what()).c_str());
    return 2;
  }
  return 0;
}

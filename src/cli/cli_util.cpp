// Helpers of the subcommands that run voxcone itself in child processes.

#include "cli_util.h"

#include "voxcone/core/error.h"

#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <filesystem>

namespace voxcone {

std::string shellQuote(const std::string& s) {
  std::string r = "'";
  for (char c : s) r += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return r + "'";
}

int runCapture(const std::string& cmd, std::string& out) {
  FILE* p = ::popen(cmd.c_str(), "r");
  if (!p) throw Error("cannot run: " + cmd);
  std::array<char, 4096> buf;
  size_t n;
  while ((n = std::fread(buf.data(), 1, buf.size(), p)) > 0) out.append(buf.data(), n);
  const int status = ::pclose(p);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string selfExe() {
  std::error_code ec;
  const auto p = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (ec) throw Error("cannot locate the voxcone executable");
  return p.string();
}

}  // namespace voxcone

#pragma once
// Helpers of the subcommands that run voxcone itself in child processes (study, batch).

#include <string>

namespace voxcone {

/// `s` quoted for /bin/sh.
std::string shellQuote(const std::string& s);

/// Run `cmd` through /bin/sh and capture its stdout; returns the exit status (-1 when it did
/// not exit normally). Throws Error when it cannot be started.
int runCapture(const std::string& cmd, std::string& out);

/// Path of the running voxcone executable.
std::string selfExe();

}  // namespace voxcone

#pragma once
/// \file process.h
/// Child processes for batches and studies (each render its own process: its own peak RSS,
/// memory budget and crash): shell quoting, running a command with its stdout captured, passing
/// a signal on, and the running executable's path.

#include <string>

namespace voxcone {

/// `s` quoted for /bin/sh.
std::string shellQuote(const std::string& s);

/// Run `cmd` through /bin/sh and capture its stdout; returns the exit status (128 + the signal
/// when a signal ended it, as a shell says). The child gets SIGTERM if the calling thread dies
/// first (a command starting with "exec" passes that on to its program). Throws Error when it
/// cannot be started.
int runCapture(const std::string& cmd, std::string& out);

/// Send `sig` to every child runCapture is waiting for (a batch passing on SIGTERM).
void signalChildren(int sig);

/// Path of the running executable (/proc/self/exe).
std::string selfExe();

/// The last non-empty line of `s` (a child's message), without voxcone's "voxcone: error: "
/// prefix.
std::string lastLine(const std::string& s);

}  // namespace voxcone

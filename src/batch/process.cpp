// Child processes of the batch layer: shell quoting, running a command with its output
// captured (the child dies with the thread waiting for it), passing a signal on to the children
// still running, and this executable's path.

#include "voxcone/batch/process.h"
#include "voxcone/core/error.h"

#include <fcntl.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <set>
#include <sstream>

namespace voxcone {

std::string shellQuote(const std::string& s) {
  std::string r = "'";
  for (char c : s) r += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return r + "'";
}

namespace {
std::mutex g_childrenMutex;
std::set<pid_t> g_children;  ///< runCapture's children still running
}  // namespace

void signalChildren(int sig) {
  std::lock_guard<std::mutex> lock(g_childrenMutex);
  for (pid_t pid : g_children) ::kill(pid, sig);
}

int runCapture(const std::string& cmd, std::string& out) {
  // fork + exec instead of popen, so that the child gets SIGTERM when the thread waiting for it
  // dies (PR_SET_PDEATHSIG; kept across exec): a batch killed with SIGKILL used to leave its
  // render running and writing into the output folder. Commands that start with "exec" hand
  // that on from the shell to the program.
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0) throw Error("cannot run: " + cmd + ": " + std::strerror(errno));
  const pid_t parent = ::getpid();
  const char* command = cmd.c_str();
  const pid_t pid = ::fork();
  if (pid < 0) {
    ::close(fds[0]);
    ::close(fds[1]);
    throw Error("cannot run: " + cmd + ": " + std::strerror(errno));
  }
  if (pid == 0) {  // only async-signal-safe calls until exec
    ::prctl(PR_SET_PDEATHSIG, SIGTERM);
    if (::getppid() != parent) ::_exit(127);  // the parent died before prctl took effect
    ::dup2(fds[1], STDOUT_FILENO);
    ::execl("/bin/sh", "sh", "-c", command, static_cast<char*>(nullptr));
    ::_exit(127);
  }
  {
    std::lock_guard<std::mutex> lock(g_childrenMutex);
    g_children.insert(pid);
  }
  ::close(fds[1]);
  std::array<char, 4096> buf;
  for (;;) {
    const ssize_t n = ::read(fds[0], buf.data(), buf.size());
    if (n > 0) out.append(buf.data(), size_t(n));
    else if (n == 0 || errno != EINTR) break;
  }
  ::close(fds[0]);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  {
    std::lock_guard<std::mutex> lock(g_childrenMutex);
    g_children.erase(pid);
  }
  if (WIFSIGNALED(status)) return 128 + WTERMSIG(status);  // as a shell reports it
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::string selfExe() {
  std::error_code ec;
  const auto p = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (ec) throw Error("cannot locate the voxcone executable");
  return p.string();
}

std::string lastLine(const std::string& s) {
  std::istringstream in(s);
  std::string line, last;
  while (std::getline(in, line))
    if (!line.empty()) last = line;
  const std::string prefix = "voxcone: error: ";
  if (last.rfind(prefix, 0) == 0) last = last.substr(prefix.size());
  return last;
}

}  // namespace voxcone

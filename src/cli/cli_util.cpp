// Helpers of the subcommands that run voxcone itself in child processes.

#include "cli_util.h"

#include "voxcone/core/error.h"
#include "voxcone/image/image_io.h"

#include <nlohmann/json.hpp>

#include <fcntl.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <set>

namespace voxcone {

const CLI::Validator& nonEmpty() {
  static const CLI::Validator v([](std::string& s) { return s.empty() ? std::string("must not be empty") : std::string(); },
                                "NONEMPTY");
  return v;
}

const CLI::Validator& positiveNumber() {
  static const CLI::Validator v(
      [](std::string& s) {
        char* end = nullptr;
        const double d = std::strtod(s.c_str(), &end);
        const bool ok = !s.empty() && end == s.c_str() + s.size() && std::isfinite(d) && d > 0.0;
        return ok ? std::string() : "expects a positive number, got '" + s.substr(0, 40) + "'";
      },
      "POSITIVE");
  return v;
}

uint64_t parseSeed(const std::string& option, const std::string& text) {
  uint64_t v = 0;
  const char* end = text.data() + text.size();
  const auto [ptr, ec] = std::from_chars(text.data(), end, v);
  if (text.empty() || ec != std::errc() || ptr != end)
    throw SettingsError(option + ": expected an integer in [0, 18446744073709551615], got '" + text.substr(0, 40) + "'");
  return v;
}

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

void addSchedulerOptions(CLI::App& cmd, StudyScheduler& scheduler) {
  cmd.add_flag("--slurm", scheduler.slurm,
               "Run the renders as a Slurm job array (batch --slurm --wait) and merge what its tasks wrote");
  cmd.add_option("--partition", scheduler.partition, "--slurm: the partition to submit to");
  cmd.add_option("--time", scheduler.timeLimit, "--slurm: each task's time limit (e.g. 30:00)");
  cmd.add_option("--shards", scheduler.shards, "--slurm: array tasks (default: one per render)")
      ->check(CLI::Range(1, 1000000));
}

nlohmann::json runStudyBatch(const nlohmann::json& manifest, const std::string& outDir, int jobsInFlight,
                             int threadsPerJob, const StudyScheduler& scheduler) {
  std::filesystem::create_directories(outDir);
  const std::string manifestPath = outDir + "/manifest.json";
  writeJsonAtomic(manifestPath, manifest);
  std::string out;
  // The batch's stderr is the study's: its "[i/N] job elapsed eta: status" lines are the
  // study's progress.
  std::string cmd = "exec " + shellQuote(selfExe()) + " batch " + shellQuote(manifestPath) + " -o " +
                    shellQuote(outDir + "/runs") + " -j " + std::to_string(jobsInFlight) + " -t " +
                    std::to_string(threadsPerJob);
  if (!scheduler.slurm) {
    cmd += " --skip-existing";
  } else {
    // Each task skips what exists; --wait then merges the shards into runs/results.json.
    cmd += " --slurm --wait";
    if (!scheduler.partition.empty()) cmd += " --partition " + shellQuote(scheduler.partition);
    if (!scheduler.timeLimit.empty()) cmd += " --time " + shellQuote(scheduler.timeLimit);
    if (scheduler.shards > 0) cmd += " --shards " + std::to_string(scheduler.shards);
  }
  const int code = runCapture(cmd, out);
  if (code == 128 + SIGINT || code == 128 + SIGTERM) throw CancelledError("the study's batch was interrupted; run it again to resume");
  if (code != 0 && code != 1) throw Error("batch failed (exit status " + std::to_string(code) + "; its message is above)");
  std::ifstream f(outDir + "/runs/results.json");
  if (!f) throw Error("batch wrote no " + outDir + "/runs/results.json");
  return nlohmann::json::parse(f);
}

void runChartScript(const std::string& script, const std::string& studyJson, const std::string& outStem) {
  std::string out;
  const std::string cmd = "/usr/bin/python3 " + shellQuote(script) + " " + shellQuote(studyJson) + " " +
                          shellQuote(outStem) + " 2>&1";
  if (runCapture(cmd, out) != 0) throw Error("chart script failed: " + out.substr(0, out.find('\n')));
  std::printf("%s", out.c_str());
}

}  // namespace voxcone

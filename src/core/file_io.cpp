// Atomic file writes (file_io.h): a temporary beside the target, renamed over it.

#include "voxcone/core/file_io.h"

#include "voxcone/core/error.h"

#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <charconv>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>

namespace voxcone {

namespace {

namespace fs = std::filesystem;

/// Counter making temporary names unique within one process (several threads may write).
std::atomic<unsigned> g_tmpCounter{0};

/// Remove temporaries of `target` (".<stem>.tmp-<pid>-<n><ext>") left by a process that no
/// longer exists (killed with SIGKILL mid-write: nothing else would ever remove them).
void removeStaleTemporaries(const fs::path& dir, const fs::path& target) {
  const std::string prefix = "." + target.stem().string() + ".tmp-", ext = target.extension().string();
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.size() <= prefix.size() + ext.size() || name.compare(0, prefix.size(), prefix) != 0 ||
        name.compare(name.size() - ext.size(), ext.size(), ext) != 0)
      continue;
    const std::string rest = name.substr(prefix.size());  // "<pid>-<n><ext>"
    long pid = 0;
    const auto [ptr, perr] = std::from_chars(rest.data(), rest.data() + rest.size(), pid);
    if (perr != std::errc() || ptr == rest.data() || *ptr != '-' || pid <= 0) continue;
    if (pid == long(::getpid())) continue;
    if (::kill(pid_t(pid), 0) == 0 || errno != ESRCH) continue;  // alive, or not ours to judge
    std::error_code rm;
    fs::remove(it->path(), rm);
  }
}

}  // namespace

std::string temporaryPathFor(const std::string& path) {
  const fs::path target(path);
  if (target.filename().empty()) throw Error(path + ": not a file path");
  const fs::path dir = target.parent_path().empty() ? fs::path(".") : target.parent_path();
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw Error(path + ": directory " + dir.string() + " does not exist");
  removeStaleTemporaries(dir, target);
  const std::string tmpName = "." + target.stem().string() + ".tmp-" + std::to_string(::getpid()) + "-" +
                              std::to_string(g_tmpCounter.fetch_add(1)) + target.extension().string();
  return (dir / tmpName).string();
}

void writeFileAtomic(const std::string& path, const std::function<void(const std::string& tmpPath)>& writer) {
  const std::string tmpPath = temporaryPathFor(path);
  std::error_code ec;
  try {
    writer(tmpPath);
    if (std::rename(tmpPath.c_str(), path.c_str()) != 0)
      throw Error(path + ": cannot rename temporary file " + tmpPath + ": " + std::strerror(errno));
  } catch (...) {
    fs::remove(tmpPath, ec);
    throw;
  }
}

}  // namespace voxcone

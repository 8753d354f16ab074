// Files written as a set (OutputSet), JSON written atomically, and the atomic write of an image
// (image_io.h).

#include "image_io_impl.h"

#include "voxcone/core/error.h"
#include "voxcone/core/file_io.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>

namespace voxcone {

namespace fs = std::filesystem;

OutputSet::~OutputSet() {
  if (m_committed) return;
  std::error_code ec;
  for (const Entry& e : m_entries) fs::remove(e.tmp, ec);
}

void OutputSet::add(const std::string& path, const std::function<void(const std::string& tmpPath)>& writer) {
  const std::string tmp = temporaryPathFor(path);
  try {
    writer(tmp);
  } catch (...) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw;
  }
  std::lock_guard<std::mutex> lock(m_mutex);
  m_entries.push_back({path, tmp});
}

void OutputSet::commit(const std::string& last) {
  std::lock_guard<std::mutex> lock(m_mutex);
  // `last` (the sidecar that marks a set complete) is renamed after every other file.
  std::stable_partition(m_entries.begin(), m_entries.end(), [&](const Entry& e) { return e.path != last; });
  for (size_t i = 0; i < m_entries.size(); ++i) {
    if (std::rename(m_entries[i].tmp.c_str(), m_entries[i].path.c_str()) == 0) continue;
    const std::string why = std::strerror(errno);
    // Not part of a set: the files renamed before this one go, and the temporaries after it.
    std::error_code ec;
    for (size_t k = 0; k < m_entries.size(); ++k) fs::remove(k < i ? m_entries[k].path : m_entries[k].tmp, ec);
    m_committed = true;
    throw Error(m_entries[i].path + ": cannot rename temporary file " + m_entries[i].tmp + ": " + why);
  }
  m_committed = true;
}

void writeJsonAtomic(const std::string& path, const nlohmann::json& value, OutputSet* set) {
  std::string text;
  try {
    text = value.dump(2) + "\n";
  } catch (const nlohmann::json::exception& e) {
    throw Error(path + ": cannot serialise JSON: " + e.what());
  }
  const auto writer = [&](const std::string& tmpPath) {
    std::ofstream file(tmpPath, std::ios::binary | std::ios::trunc);
    if (!file) throw Error(path + ": cannot open temporary file " + tmpPath + ": " + std::strerror(errno));
    file << text;
    file.close();
    if (!file) throw Error(path + ": cannot write temporary file " + tmpPath);
  };
  if (set) set->add(path, writer);
  else writeFileAtomic(path, writer);
}

namespace image_io {

void writeImageAtomic(const std::string& path, const std::function<void(const std::string& tmpPath)>& writer,
                      OutputSet* set) {
  if (set) {
    set->add(path, writer);
    return;
  }
  // The temporary's naming and renaming report Error; an image write reports ImageError.
  try {
    writeFileAtomic(path, writer);
  } catch (const ImageError&) {
    throw;
  } catch (const Error& e) {
    throw ImageError(e.what());
  }
}

}  // namespace image_io

}  // namespace voxcone

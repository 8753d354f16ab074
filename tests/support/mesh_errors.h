#pragma once
// Expect a loader to reject a file with a one-line MeshError that names the file.

#include "voxcone/core/error.h"
#include "voxcone/scene/mesh.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <string>

namespace voxcone::test {

/// `load(path)` must throw MeshError whose one-line message names the file (and contains
/// `needle` when given); any other outcome is a test failure.
template <typename Loader>
void expectMeshError(Loader&& load, const std::string& path, const std::string& needle = "") {
  try {
    load(path);
    ADD_FAILURE() << "no MeshError for " << path;
  } catch (const MeshError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(std::filesystem::path(path).filename().string()), std::string::npos) << msg;
    EXPECT_EQ(msg.find('\n'), std::string::npos) << "message not one line: " << msg;
    if (!needle.empty()) {
      EXPECT_NE(msg.find(needle), std::string::npos) << msg;
    }
  } catch (const std::exception& e) {
    ADD_FAILURE() << "wrong exception type for " << path << ": " << e.what();
  }
}

}  // namespace voxcone::test

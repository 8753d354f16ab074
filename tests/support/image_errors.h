#pragma once
// Expect readImage to reject a file with a one-line ImageError that names the file.

#include "voxcone/core/error.h"
#include "voxcone/image/image_io.h"

#include <gtest/gtest.h>

#include <string>

namespace voxcone::test {

/// readImage(file) must throw ImageError whose one-line message names the file (and contains
/// `mentions` when given); any other outcome is a test failure.
inline void expectOneLineImageError(const std::string& file, const std::string& mentions = "") {
  try {
    readImage(file);
    ADD_FAILURE() << "no exception for " << file;
  } catch (const ImageError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(file), std::string::npos) << msg;
    EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
    if (!mentions.empty()) {
      EXPECT_NE(msg.find(mentions), std::string::npos) << msg;
    }
  }
}

}  // namespace voxcone::test

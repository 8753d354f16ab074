#pragma once
// Print a test's measured value next to the bound it asserts, and record it as a property; a
// channel-wise check that returns what it measured.

#include "voxcone/core/math.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <string>

namespace voxcone::test {

/// One line "[measured] Suite.Test: what = measured (bound bound)" on stdout; also recorded in
/// the XML output as the property "what" (non-alphanumerics as '_'), value "measured (bound b)".
/// Without a bound (a value the test prints but does not assert): "(no bound)".
inline void report(const std::string& what, double measured, double bound = std::nan("")) {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const std::string name = info ? std::string(info->test_suite_name()) + "." + info->name() : "?";
  char value[96];
  if (std::isnan(bound))
    std::snprintf(value, sizeof value, "%.6g (no bound)", measured);
  else
    std::snprintf(value, sizeof value, "%.6g (bound %.6g)", measured, bound);
  std::printf("[measured] %s: %s = %s\n", name.c_str(), what.c_str(), value);
  std::fflush(stdout);
  std::string key = what;
  for (char& c : key)
    if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
  ::testing::Test::RecordProperty(key, value);
}

/// EXPECT_NEAR on each channel of a and b; returns the largest channel error, for report().
inline float expectVecNear(const Vec3& a, const Vec3& b, float tol, const std::string& what = "") {
  float worst = 0.0f;
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(a[c], b[c], tol) << what << " channel " << c;
    worst = std::max(worst, std::fabs(a[c] - b[c]));
  }
  return worst;
}

}  // namespace voxcone::test

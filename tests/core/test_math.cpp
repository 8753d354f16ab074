// Small math helpers against the library functions they replace.

#include "voxcone/core/math.h"

#include <gtest/gtest.h>

namespace voxcone {
namespace {

TEST(Math, PowersOfTwoMatchExp2OfFloorAndCeilOfLog2) {
  for (float x : {1.0f, 1.5f, 2.0f, 3.0f, 0.75f, 0.5f, 1000.0f, 1024.0f, 1e-20f, 3e30f, 0.1f, 7.999f}) {
    EXPECT_EQ(floorPow2(x), std::exp2(std::floor(std::log2(double(x))))) << x;
    EXPECT_EQ(ceilPow2(x), std::exp2(std::ceil(std::log2(double(x))))) << x;
  }
  // Just above a power of two the ceiling is the next one.
  EXPECT_EQ(ceilPow2(std::nextafter(4.0f, 8.0f)), 8.0f);
  EXPECT_EQ(floorPow2(std::nextafter(4.0f, 0.0f)), 2.0f);
}

}  // namespace
}  // namespace voxcone

/// \file test_film.cpp
/// The film's sums and means by hand: the beauty and a layer over the samples taken, and the
/// last complete pass kept and restored.

#include "voxcone/image/film.h"

#include <gtest/gtest.h>

namespace voxcone {
namespace {

TEST(Film, MeansAreTheSumsOverTheSamplesTaken) {
  Film film(3, 2, {{"albedo", {"Albedo.R", "Albedo.G", "Albedo.B"}}, {"depth", {"Z"}}});
  ASSERT_TRUE(film.hasLayers());
  // Pixel (2, 1) = index 5: four samples of the beauty (1, 2, 3) + (3, 2, 1) ... summing to
  // (8, 8, 8); the depth layer 0.5 each time, the albedo only in its green channel.
  for (int s = 0; s < 4; ++s) {
    film.beauty(5) += s % 2 ? DVec3(3.0, 2.0, 1.0) : DVec3(1.0, 2.0, 3.0);
    film.layerSums(5, 1)[0] += 0.5;
    film.layerSums(5, 0)[1] += 0.25;
  }
  const Image img = film.image(4);
  ASSERT_EQ(img.width, 3);
  ASSERT_EQ(img.height, 2);
  EXPECT_EQ(img.pixels[5], Vec3(2.0f, 2.0f, 2.0f));
  EXPECT_EQ(img.pixels[0], Vec3(0.0f));
  const std::vector<ImageLayer> layers = film.layers(4);
  ASSERT_EQ(layers.size(), 2u);
  EXPECT_EQ(layers[0].name, "albedo");
  ASSERT_EQ(layers[0].values.size(), 6u * 3u);
  EXPECT_FLOAT_EQ(layers[0].values[5 * 3 + 1], 0.25f);
  EXPECT_FLOAT_EQ(layers[0].values[5 * 3 + 0], 0.0f);
  ASSERT_EQ(layers[1].values.size(), 6u);
  EXPECT_FLOAT_EQ(layers[1].values[5], 0.5f);
}

TEST(Film, AnInterruptedPassFallsBackToTheLastCompleteOne) {
  Film film(1, 1);
  EXPECT_FALSE(film.hasLayers());
  EXPECT_TRUE(film.layers(1).empty());
  film.beauty(0) += DVec3(1.0);
  film.keepComplete();
  film.beauty(0) += DVec3(100.0);  // half a pass, then interrupted
  film.restoreComplete();
  EXPECT_EQ(film.image(1).pixels[0], Vec3(1.0f));
}

}  // namespace
}  // namespace voxcone

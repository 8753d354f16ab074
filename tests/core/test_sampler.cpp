// The pixel sampler: stratification of every slot, determinism, and the independent kind.

#include "voxcone/core/error.h"
#include "voxcone/core/sampler.h"

#include <gtest/gtest.h>

#include <set>

namespace voxcone {
namespace {

TEST(Sampler, SobolDimensionsAreTheKnownSequences) {
  // The radical inverse and Sobol's second dimension at the first indices, hand-computed from
  // the direction numbers 1/2, 3/4, 5/8 (index i xors those of its set bits; no Gray code):
  // 0, 1/2, 3/4, 1/4, 5/8, 1/8.
  EXPECT_EQ(sobolDim0(1), 0x80000000u);
  EXPECT_EQ(sobolDim0(2), 0x40000000u);
  EXPECT_EQ(sobolDim0(3), 0xc0000000u);
  const uint32_t dim1[] = {0x00000000u, 0x80000000u, 0xc0000000u, 0x40000000u, 0xa0000000u, 0x20000000u};
  for (uint32_t i = 0; i < 6; ++i) EXPECT_EQ(sobolDim1(i), dim1[i]) << i;
  EXPECT_EQ(reverseBits32(1u), 0x80000000u);
  EXPECT_EQ(reverseBits32(0x12345678u), 0x1e6a2c48u);
}

TEST(Sampler, OwenScrambleIsABijectionThatKeepsStrata) {
  // Values in one 1/2^k interval stay together (the top k bits of the result depend only on the
  // top k bits of the input), and distinct inputs give distinct outputs.
  std::set<uint32_t> seen;
  for (uint32_t v = 0; v < 4096; ++v) {
    const uint32_t a = owenScramble(v << 20, 0xdeadbeefu);
    EXPECT_TRUE(seen.insert(a >> 20).second);
    EXPECT_EQ(owenScramble((v << 20) | 0x5a5a5u, 0xdeadbeefu) >> 20, a >> 20);
  }
}

TEST(Sampler, EverySlotOfAPixelIsAStratifiedNet) {
  // 64 samples: in every slot the 2D points fill each of the 2^a x 2^b boxes (a + b = 6)
  // exactly once, and the 1D values each 1/64 interval once; all in [0, 1).
  constexpr int kSpp = 64;
  Sampler sampler(SamplerKind::Sobol, 17, 12345);
  constexpr int kSlots = 12;
  std::vector<std::vector<Vec2>> points(kSlots);
  std::vector<std::vector<float>> values(kSlots);
  for (int i = 0; i < kSpp; ++i) {
    sampler.startSample(uint32_t(i));
    for (int slot = 0; slot < kSlots; ++slot) {
      if (slot % 3 == 2) {
        values[slot].push_back(sampler.uniform());
      } else {
        points[slot].push_back(sampler.uniform2());
      }
    }
  }
  for (int slot = 0; slot < kSlots; ++slot) {
    if (slot % 3 == 2) {
      std::set<int> strata;
      for (float v : values[slot]) {
        ASSERT_TRUE(v >= 0.0f && v < 1.0f);
        strata.insert(int(v * kSpp));
      }
      EXPECT_EQ(strata.size(), size_t(kSpp)) << "slot " << slot;
      continue;
    }
    for (int a = 0; a <= 6; ++a) {
      std::set<std::pair<int, int>> boxes;
      for (const Vec2& p : points[slot]) {
        ASSERT_TRUE(p.x >= 0.0f && p.x < 1.0f && p.y >= 0.0f && p.y < 1.0f);
        boxes.insert({int(p.x * float(1 << a)), int(p.y * float(1 << (6 - a)))});
      }
      EXPECT_EQ(boxes.size(), size_t(kSpp)) << "slot " << slot << ", boxes 2^" << a << " x 2^" << 6 - a;
    }
  }
}

TEST(Sampler, SlotsAndPixelsAreDecorrelatedAndDeterministic) {
  Sampler a(SamplerKind::Sobol, 3, 10), b(SamplerKind::Sobol, 3, 10), c(SamplerKind::Sobol, 3, 11);
  a.startSample(5);
  b.startSample(5);
  c.startSample(5);
  const Vec2 a0 = a.uniform2(), a1 = a.uniform2();
  EXPECT_EQ(a0, b.uniform2());  // the same (seed, pixel, sample, slot): the same value
  EXPECT_EQ(a1, b.uniform2());
  EXPECT_NE(a0, a1);            // slots differ
  EXPECT_NE(a0, c.uniform2());  // pixels differ
  // Sample i of a pixel does not depend on which samples were drawn before it.
  Sampler d(SamplerKind::Sobol, 3, 10);
  d.startSample(5);
  EXPECT_EQ(d.uniform2(), a0);
}

TEST(Sampler, IndependentSamplesAreTheirOwnPcgStreams) {
  // Sample i of a pixel does not depend on the samples drawn before it (renders take them in
  // passes, with a new Sampler each pass); samples, pixels and seeds differ.
  Sampler s(SamplerKind::Independent, 9, 77), t(SamplerKind::Independent, 9, 77);
  Sampler otherPixel(SamplerKind::Independent, 9, 78), otherSeed(SamplerKind::Independent, 10, 77);
  std::vector<Vec2> first;
  for (int i = 0; i < 4; ++i) {
    s.startSample(uint32_t(i));
    first.push_back(s.uniform2());
    s.uniform();
  }
  for (int i = 3; i >= 0; --i) {
    t.startSample(uint32_t(i));
    EXPECT_EQ(t.uniform2(), first[size_t(i)]);
  }
  EXPECT_NE(first[0], first[1]);
  otherPixel.startSample(0);
  otherSeed.startSample(0);
  EXPECT_NE(otherPixel.uniform2(), first[0]);
  EXPECT_NE(otherSeed.uniform2(), first[0]);
  // Within a sample the values are a PCG stream: uniform on [0, 1), mean 1/2.
  double mean = 0.0;
  for (int i = 0; i < 4096; ++i) {
    s.startSample(uint32_t(i));
    mean += s.uniform();
  }
  EXPECT_NEAR(mean / 4096.0, 0.5, 0.02);
}

TEST(Sampler, KindsByName) {
  EXPECT_EQ(samplerKindFromName("sobol"), SamplerKind::Sobol);
  EXPECT_EQ(samplerKindFromName("independent"), SamplerKind::Independent);
  EXPECT_THROW(samplerKindFromName("halton"), SettingsError);
}

}  // namespace
}  // namespace voxcone

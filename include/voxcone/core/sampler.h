#pragma once
/// \file sampler.h
/// The per-pixel sample source of every integrator: pixel jitter, light samples and BSDF
/// samples are drawn from it dimension by dimension.
///
/// `sobol` (the default): each call to uniform() or uniform2() is one dimension slot; a slot is
/// the (0,2)-sequence (Sobol's first two dimensions) under its own random Owen scramble, read
/// at the pixel sample's index shuffled by another Owen scramble. This is the "shuffled,
/// scrambled Sobol" padding of Burley 2020, "Practical Hash-based Owen Scrambling", JCGT 9(4),
/// sec. 4-5 (nested uniform scrambling by a Laine-Karras style hash), as pbrt-v4's
/// PaddedSobolSampler: within a pixel, every 2D projection the integrators use (jitter, a light
/// sample, a BSDF sample) is a scrambled (0,m,2)-net for power-of-two sample counts, so its
/// error falls faster than 1/sqrt(spp) where the integrand is smooth in those dimensions.
/// `independent`: one PCG32 stream per pixel (the sampler before this one).
///
/// Both depend on (seed, pixel index, sample index, dimension) only, never on thread or tile
/// order, so images are bit-identical at any thread count.

#include "voxcone/core/rng.h"

#include <string>
#include <vector>

namespace voxcone {

/// How a Sampler draws.
enum class SamplerKind { Sobol, Independent };

/// Names of the kinds ("sobol", "independent"), in enum order.
const std::vector<std::string>& samplerNames();
/// The kind named `name`; throws SettingsError for any other name.
SamplerKind samplerKindFromName(const std::string& name);

/// Reverse the 32 bits of v (a byte swap, then bits within bytes).
inline uint32_t reverseBits32(uint32_t v) {
  v = __builtin_bswap32(v);
  v = ((v >> 1) & 0x55555555u) | ((v & 0x55555555u) << 1);
  v = ((v >> 2) & 0x33333333u) | ((v & 0x33333333u) << 2);
  return ((v >> 4) & 0x0f0f0f0fu) | ((v & 0x0f0f0f0fu) << 4);
}

/// The Laine-Karras style permutation of Burley 2020 (listing 2) on bit-reversed values: each
/// step only carries information from lower to higher bits (an addition, xors with products by
/// even constants), so output bit k depends on input bits 0..k only.
inline uint32_t laineKarrasPermutation(uint32_t v, uint32_t seed) {
  v += seed;
  v ^= v * 0x6c50b47cu;
  v ^= v * 0xb82f1e52u;
  v ^= v * 0xc7afe638u;
  v ^= v * 0x8d22f6e6u;
  return v;
}

/// Nested uniform (Owen) scrambling of a 32-bit fixed-point value in [0,1) keyed by `seed`
/// (Burley 2020, listing 3): a bijection on 32-bit values in which each bit is flipped by a
/// hash of the bits above it, which keeps every elementary interval of a net mapped onto one.
inline uint32_t owenScramble(uint32_t v, uint32_t seed) {
  return reverseBits32(laineKarrasPermutation(reverseBits32(v), seed));
}

/// The first Sobol dimension (the base-2 radical inverse) at `index`, as 32-bit fixed point.
inline uint32_t sobolDim0(uint32_t index) { return reverseBits32(index); }

namespace detail {
/// Sobol's second dimension, bit-reversed, by bytes: the generator matrix is linear over GF(2),
/// so the value at `index` is the xor of the four bytes' contributions. Direction numbers (not
/// reversed) v_0 = 2^31, v_k = v_{k-1} xor (v_{k-1} >> 1): the upper-triangular Pascal matrix
/// mod 2 of primitive polynomial x + 1.
struct SobolDim1Table {
  uint32_t byByte[4][256];
  SobolDim1Table() {
    uint32_t reversedDirection[32];
    uint32_t v = 0x80000000u;
    for (int k = 0; k < 32; ++k, v ^= v >> 1) reversedDirection[k] = reverseBits32(v);
    for (int b = 0; b < 4; ++b)
      for (uint32_t byte = 0; byte < 256; ++byte) {
        uint32_t x = 0;
        for (int bit = 0; bit < 8; ++bit)
          if (byte & (1u << bit)) x ^= reversedDirection[8 * b + bit];
        byByte[b][byte] = x;
      }
  }
};
inline const SobolDim1Table& sobolDim1Table() {
  static const SobolDim1Table table;
  return table;
}
}  // namespace detail

/// Sobol's second dimension at `index`, bit-reversed (the form the scrambling works on).
inline uint32_t sobolDim1Reversed(uint32_t index) {
  const auto& t = detail::sobolDim1Table().byByte;
  return t[0][index & 0xffu] ^ t[1][(index >> 8) & 0xffu] ^ t[2][(index >> 16) & 0xffu] ^ t[3][index >> 24];
}

/// Sobol's second dimension at `index`, as 32-bit fixed point.
inline uint32_t sobolDim1(uint32_t index) { return reverseBits32(sobolDim1Reversed(index)); }

/// Samples of one pixel. startSample(i) begins sample i at dimension 0; each uniform() or
/// uniform2() then takes the next dimension slot.
class Sampler {
public:
  /// The sampler of pixel `pixel` (y * width + x) for render seed `seed`, which will take
  /// `samplesPerPixel` samples (integrators that spend some work on only a few of a pixel's
  /// samples weight it by this count).
  Sampler(SamplerKind kind, uint64_t seed, uint64_t pixel, uint32_t samplesPerPixel = 1)
      : m_kind(kind), m_rng(seed, pixel), m_pixelKey(mixBits(mixBits(seed) ^ (pixel + 0x632be59bd9b4e019ULL))),
        m_pixel(pixel), m_samplesPerPixel(samplesPerPixel) {}

  SamplerKind kind() const { return m_kind; }
  /// The index of the current sample (startSample's argument).
  uint32_t sampleIndex() const { return m_index; }
  /// The number of samples the pixel takes.
  uint32_t samplesPerPixel() const { return m_samplesPerPixel; }

  /// Begin the pixel's sample `index` (0, 1, ... spp-1), at dimension 0.
  void startSample(uint32_t index) {
    // Independent: each sample its own PCG stream (pixel, and the pixel's key with the index),
    // so that sample i never depends on the samples drawn before it (renders in passes).
    if (m_kind == SamplerKind::Independent)
      m_rng.setStream(mixBits(m_pixelKey + 0x9e3779b97f4a7c15ULL * (uint64_t(index) + 1)), m_pixel);
    m_index = index;
    m_reversedIndex = reverseBits32(index);
    m_dimension = 0;
  }

  /// Uniform in [0, 1).
  float uniform() {
    if (m_kind == SamplerKind::Independent) return m_rng.uniform();
    const uint64_t key = slotKey();
    // owenScramble(sobolDim0(shuffled)), whose reversals cancel: the shuffled index is the
    // reversed radical inverse already.
    return toUnit(reverseBits32(laineKarrasPermutation(shuffledIndex(key), uint32_t(key >> 32))));
  }

  /// Uniform in [0, 1)^2, the two coordinates of one stratified dimension slot.
  Vec2 uniform2() {
    if (m_kind == SamplerKind::Independent) return m_rng.uniform2();
    const uint64_t key = slotKey();
    const uint32_t shuffled = shuffledIndex(key);
    const uint32_t x = reverseBits32(laineKarrasPermutation(shuffled, uint32_t(key >> 32)));
    const uint32_t y = reverseBits32(laineKarrasPermutation(sobolDim1Reversed(shuffled), uint32_t(mixBits(key) >> 32)));
    return Vec2(toUnit(x), toUnit(y));
  }

private:
  /// The next slot's scrambling keys, from the pixel and the dimension only.
  uint64_t slotKey() { return mixBits(m_pixelKey + 0x9e3779b97f4a7c15ULL * (uint64_t(m_dimension++) + 1)); }
  /// The sample index under this slot's nested scramble (Burley's shuffle): owenScramble(index,
  /// key).
  uint32_t shuffledIndex(uint64_t key) const {
    return reverseBits32(laineKarrasPermutation(m_reversedIndex, uint32_t(key)));
  }
  static float toUnit(uint32_t v) { return std::min(kOneMinusEpsilon, float(v) * 0x1p-32f); }

  SamplerKind m_kind;
  Rng m_rng;
  uint64_t m_pixelKey;
  uint64_t m_pixel;
  uint32_t m_samplesPerPixel = 1;
  uint32_t m_index = 0;
  uint32_t m_reversedIndex = 0;  ///< m_index bit-reversed, once per sample
  uint32_t m_dimension = 0;
};

}  // namespace voxcone

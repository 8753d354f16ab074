#pragma once
/// \file rng.h
/// PCG32 random numbers (O'Neill 2014, "PCG: A Family of Simple Fast Space-Efficient
/// Statistically Good Algorithms for Random Number Generation") and stream derivation.

#include "voxcone/core/math.h"

#include <cstdint>

namespace voxcone {

/// 64-bit mix (MurmurHash3 finalizer): derives well-spread stream ids from (seed, index).
inline uint64_t mixBits(uint64_t v) {
  v ^= v >> 33;
  v *= 0xff51afd7ed558ccdULL;
  v ^= v >> 33;
  v *= 0xc4ceb9fe1a85ec53ULL;
  v ^= v >> 33;
  return v;
}

/// PCG32 (XSH-RR). A generator is identified by (seed, stream): the same pair always gives the
/// same sequence, which is how results stay identical at any thread count.
class Rng {
public:
  Rng() { setStream(0, 0); }
  Rng(uint64_t seed, uint64_t stream) { setStream(seed, stream); }

  /// Start the sequence for (seed, stream), e.g. (render seed, pixel index).
  void setStream(uint64_t seed, uint64_t stream) {
    m_state = 0u;
    m_inc = (mixBits(stream ^ 0x9e3779b97f4a7c15ULL) << 1u) | 1u;
    nextU32();
    m_state += mixBits(seed + 0x2545f4914f6cdd1dULL);
    nextU32();
  }

  uint32_t nextU32() {
    const uint64_t old = m_state;
    m_state = old * 0x5851f42d4c957f2dULL + m_inc;
    const uint32_t xorshifted = static_cast<uint32_t>(((old >> 18u) ^ old) >> 27u);
    const uint32_t rot = static_cast<uint32_t>(old >> 59u);
    return (xorshifted >> rot) | (xorshifted << ((~rot + 1u) & 31));
  }

  /// Uniform float in [0, 1).
  float uniform() { return std::min(kOneMinusEpsilon, static_cast<float>(nextU32()) * 0x1p-32f); }
  Vec2 uniform2() {
    const float a = uniform();
    return Vec2(a, uniform());
  }

private:
  uint64_t m_state = 0;
  uint64_t m_inc = 1;
};

}  // namespace voxcone

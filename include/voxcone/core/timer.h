#pragma once
/// \file timer.h
/// Wall-clock timing and process memory.

#include <chrono>
#include <cstdint>

namespace voxcone {

/// Wall-clock stopwatch, seconds.
class Timer {
public:
  Timer() : m_start(std::chrono::steady_clock::now()) {}
  void reset() { m_start = std::chrono::steady_clock::now(); }
  double seconds() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - m_start).count();
  }

private:
  std::chrono::steady_clock::time_point m_start;
};

/// Peak resident set size of this process, bytes (0 where unknown).
uint64_t peakRssBytes();
/// Current resident set size of this process, bytes (0 where unknown).
uint64_t currentRssBytes();
/// Memory the machine can give without swapping (MemAvailable of /proc/meminfo), bytes (0
/// where unknown).
uint64_t availableMemoryBytes();

}  // namespace voxcone

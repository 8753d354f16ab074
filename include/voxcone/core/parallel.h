#pragma once
/// \file parallel.h
/// Thread-count control for TBB.

#include <tbb/global_control.h>

#include <memory>

namespace voxcone {

/// Limits TBB to `threads` workers while alive (0 = all hardware threads).
class ThreadLimit {
public:
  explicit ThreadLimit(int threads);
  ThreadLimit(const ThreadLimit&) = delete;
  ThreadLimit& operator=(const ThreadLimit&) = delete;
  /// The number of threads in effect.
  int threads() const { return m_threads; }

private:
  std::unique_ptr<tbb::global_control> m_control;
  int m_threads;
};

/// Number of hardware threads TBB would use by default.
int hardwareThreads();

}  // namespace voxcone

#include "voxcone/core/parallel.h"

#include "voxcone/core/error.h"

#include <tbb/info.h>

namespace voxcone {

int hardwareThreads() { return tbb::info::default_concurrency(); }

ThreadLimit::ThreadLimit(int threads) {
  if (threads < 0) throw SettingsError("threads must be >= 0 (0 = all), got " + std::to_string(threads));
  m_threads = threads == 0 ? hardwareThreads() : threads;
  m_control = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                    static_cast<size_t>(m_threads));
}

}  // namespace voxcone

#pragma once
/// \file progress.h
/// Progress reporting and cancellation for long stages (cf. OpenVDB's util::NullInterrupter).

#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>

namespace voxcone {

/// Receives progress of a long stage. The default does nothing and never cancels.
/// Thread-safe: `advance` may be called from worker threads.
class Progress {
public:
  virtual ~Progress() = default;
  /// A stage named `stage` begins with `total` units of work.
  virtual void start(const std::string& stage, uint64_t total) {}
  /// `units` more units are done.
  virtual void advance(uint64_t units) {}
  /// The stage is finished.
  virtual void finish() {}
  /// True when the caller asked to stop; stages check it between work items.
  virtual bool cancelled() const { return false; }
};

/// A progress bar with elapsed time and ETA on stderr. When stderr is not a terminal it prints
/// a plain line at most every `lineIntervalSec` seconds instead of redrawing.
class ConsoleProgress final : public Progress {
public:
  explicit ConsoleProgress(bool quiet = false, double lineIntervalSec = 5.0);
  void start(const std::string& stage, uint64_t total) override;
  void advance(uint64_t units) override;
  void finish() override;
  bool cancelled() const override;

private:
  void draw(bool force);
  bool m_quiet;
  bool m_tty;
  double m_interval;
  std::string m_stage;
  uint64_t m_total = 0;
  std::atomic<uint64_t> m_done{0};
  std::mutex m_mutex;
  std::chrono::steady_clock::time_point m_start, m_lastDraw;
};

/// A duration as MM:SS, or H:MM:SS from an hour on; "--:--" when unknown or absurd.
std::string formatDuration(double sec);

/// Install SIGINT/SIGTERM handlers that make every ConsoleProgress report `cancelled()`.
void installInterruptHandler();
/// True once SIGINT or SIGTERM arrived.
bool interruptRequested();
/// The signal that asked to stop (SIGINT or SIGTERM), 0 when none did.
int interruptSignal();
/// The exit status of a process stopped by interruptSignal(): 128 + the signal, as a shell
/// reports a process the signal killed (130 SIGINT, 143 SIGTERM); 130 when none arrived.
int interruptedExitCode();

}  // namespace voxcone

#include "voxcone/core/progress.h"

#include <csignal>
#include <cstdio>
#include <unistd.h>

namespace voxcone {

namespace {
volatile std::sig_atomic_t g_interrupted = 0;  // the first signal's number
extern "C" void onInterrupt(int sig) {
  if (!g_interrupted) g_interrupted = sig;
}

}  // namespace

std::string formatDuration(double sec) {
  if (!(sec >= 0.0) || sec > 1e7) return "--:--";
  const long s = static_cast<long>(sec + 0.5);
  char buf[32];
  if (s >= 3600)
    std::snprintf(buf, sizeof(buf), "%ld:%02ld:%02ld", s / 3600, (s / 60) % 60, s % 60);
  else
    std::snprintf(buf, sizeof(buf), "%02ld:%02ld", s / 60, s % 60);
  return buf;
}

void installInterruptHandler() {
  std::signal(SIGINT, onInterrupt);
  std::signal(SIGTERM, onInterrupt);
}

bool interruptRequested() { return g_interrupted != 0; }

int interruptSignal() { return g_interrupted; }

int interruptedExitCode() { return 128 + (g_interrupted ? int(g_interrupted) : SIGINT); }

ConsoleProgress::ConsoleProgress(bool quiet, double lineIntervalSec)
    : m_quiet(quiet), m_tty(isatty(fileno(stderr)) != 0), m_interval(lineIntervalSec) {}

void ConsoleProgress::start(const std::string& stage, uint64_t total) {
  std::lock_guard<std::mutex> lock(m_mutex);
  m_stage = stage;
  m_total = total;
  m_done = 0;
  m_start = m_lastDraw = std::chrono::steady_clock::now();
}

void ConsoleProgress::advance(uint64_t units) {
  m_done += units;
  if (m_quiet) return;
  std::unique_lock<std::mutex> lock(m_mutex, std::try_to_lock);
  if (lock.owns_lock()) draw(false);
}

void ConsoleProgress::finish() {
  if (m_quiet) return;
  std::lock_guard<std::mutex> lock(m_mutex);
  m_done = m_total;
  draw(true);
  if (m_tty) std::fputc('\n', stderr);
  std::fflush(stderr);
}

bool ConsoleProgress::cancelled() const { return interruptRequested(); }

void ConsoleProgress::draw(bool force) {
  const auto now = std::chrono::steady_clock::now();
  const double sinceDraw = std::chrono::duration<double>(now - m_lastDraw).count();
  if (!force && sinceDraw < (m_tty ? 0.1 : m_interval)) return;
  m_lastDraw = now;
  const double elapsed = std::chrono::duration<double>(now - m_start).count();
  const uint64_t done = std::min<uint64_t>(m_done.load(), m_total);
  const double frac = m_total ? static_cast<double>(done) / static_cast<double>(m_total) : 1.0;
  const double eta = frac > 0.0 ? elapsed * (1.0 - frac) / frac : -1.0;
  if (m_tty) {
    constexpr int kWidth = 30;
    const int filled = static_cast<int>(frac * kWidth);
    std::string bar(static_cast<size_t>(filled), '#');
    bar.append(static_cast<size_t>(kWidth - filled), '.');
    std::fprintf(stderr, "\r%-10s [%s] %5.1f%%  elapsed %s  eta %s ", m_stage.c_str(), bar.c_str(),
                 100.0 * frac, formatDuration(elapsed).c_str(), formatDuration(eta).c_str());
  } else {
    std::fprintf(stderr, "%s: %5.1f%%  elapsed %s  eta %s\n", m_stage.c_str(), 100.0 * frac,
                 formatDuration(elapsed).c_str(), formatDuration(eta).c_str());
  }
  std::fflush(stderr);
}

}  // namespace voxcone

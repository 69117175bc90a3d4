#include "scanclean/core/progress.h"

#include <unistd.h>

#include <cstdio>
#include <cstdlib>

namespace scanclean {

bool Progress::enabled() {
  static const bool on = ::isatty(STDERR_FILENO) && std::getenv("SCANCLEAN_NO_PROGRESS") == nullptr;
  return on;
}

Progress::Progress(std::string label, std::uint64_t total)
    : label_(std::move(label)),
      total_(total),
      active_(enabled()),
      start_(std::chrono::steady_clock::now()) {}

Progress::~Progress() {
  finish();
}

void Progress::advance(std::uint64_t n) {
  const std::uint64_t done = done_.fetch_add(n, std::memory_order_relaxed) + n;
  if (!active_) return;
  const auto now = std::chrono::duration_cast<std::chrono::nanoseconds>(
                       std::chrono::steady_clock::now() - start_)
                       .count();
  auto last = last_draw_ns_.load(std::memory_order_relaxed);
  if (now - last < 100'000'000) return;
  if (!last_draw_ns_.compare_exchange_strong(last, now)) return;
  draw(done, false);
}

void Progress::finish() {
  if (!active_ || finished_) return;
  finished_ = true;
  draw(total_, true);
}

void Progress::draw(std::uint64_t done, bool final) {
  std::lock_guard<std::mutex> lock(draw_mutex_);
  const double frac = total_ ? std::min(1.0, static_cast<double>(done) / total_) : 1.0;
  const int width = 30;
  const int filled = static_cast<int>(frac * width);
  const double secs =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  std::string bar(filled, '#');
  bar.append(width - filled, '.');
  std::fprintf(stderr, "\r%-22s [%s] %5.1f%%  %6.1fs%s", label_.c_str(), bar.c_str(), 100.0 * frac,
               secs, final ? "\n" : "");
  std::fflush(stderr);
}

}  // namespace scanclean

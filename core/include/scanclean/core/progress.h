#pragma once
//! \file progress.h
//! A progress bar on stderr for long work. It draws only when stderr is a terminal, so logs and
//! pipes stay clean. advance() is thread-safe and cheap (redraws at most ~10 times a second).

#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>

namespace scanclean {

class Progress {
 public:
  Progress(std::string label, std::uint64_t total);
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  void advance(std::uint64_t n = 1);
  void finish();  //!< draws 100 % and ends the line (called by the destructor too)
  //! Whether bars are drawn (stderr is a terminal and SCANCLEAN_NO_PROGRESS is unset).
  static bool enabled();

 private:
  void draw(std::uint64_t done, bool final);
  std::string label_;
  std::uint64_t total_;
  std::atomic<std::uint64_t> done_{0};
  std::atomic<std::int64_t> last_draw_ns_{0};
  std::mutex draw_mutex_;
  bool active_;
  bool finished_ = false;
  std::chrono::steady_clock::time_point start_;
};

}  // namespace scanclean

#pragma once
//! \file replay_source.h
//! RangeSource over a recording folder (format v1), pull-based and lossless: every recorded frame
//! is delivered once, in order, with its recorded index (gaps kept) and timestamps.

#include <chrono>
#include <filesystem>
#include <functional>
#include <memory>

#include "scanclean/core/range_source.h"

namespace scanclean {

enum class Pacing {
  kAsFastAsPossible,  //!< deliver each frame as soon as asked (tests, batch processing)
  kRecorded           //!< reproduce the recorded device-timestamp deltas (host clock)
};

//! The time base of kRecorded pacing (time is an input: tests inject a fake clock).
struct ReplayClock {
  std::function<std::chrono::nanoseconds()> now;        //!< monotonic time
  std::function<void(std::chrono::nanoseconds)> sleep;  //!< blocks for (about) this long
  //! std::chrono::steady_clock and std::this_thread::sleep_for.
  static ReplayClock steady();
};

//! A source replaying `folder`. open() reads and validates the recording (RecordingReader) and
//! throws its InputError; next() decodes one frame (InputError for a corrupt PNG) and returns
//! kEndOfStream after the last frame, again on every later call. With kRecorded, frame k is
//! delivered no earlier than (ts_k - ts_0) after the first frame was delivered, where ts is
//! device_ts_us (host_ts_ns for steps where the device timestamp does not increase); when that
//! wait exceeds next()'s timeout, next() waits the timeout and returns kTimeout. info() is
//! info_from_session(session, folder) with kind "recording" and frame_count set.
//! Thread safety: one thread per source object.
std::unique_ptr<RangeSource> make_replay_source(const std::filesystem::path& folder,
                                                Pacing pacing = Pacing::kAsFastAsPossible);
//! Same, with an injected clock for kRecorded pacing.
std::unique_ptr<RangeSource> make_replay_source(const std::filesystem::path& folder, Pacing pacing,
                                                ReplayClock clock);

}  // namespace scanclean

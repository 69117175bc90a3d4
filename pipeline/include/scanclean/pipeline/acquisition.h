#pragma once
//! \file acquisition.h
//! The one place that reads frames from a RangeSource: the stop rules (frame count, seconds,
//! consecutive timeouts, end of stream, read errors, keep_going / Ctrl-C), reconnects after a
//! disconnect, and the counts of index gaps and timeouts. Used by the capture-and-clean runner
//! (pipeline.h, its acquisition stage) and by `scanclean record` (folder and .oni outputs).

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>

#include "scanclean/core/range_frame.h"
#include "scanclean/core/range_source.h"

namespace scanclean {

struct AcquisitionOptions {
  std::uint64_t max_frames = 0;             //!< stop after this many delivered frames (0 = none)
  double max_seconds = 0;                   //!< stop after this much wall time (0 = no limit)
  std::chrono::milliseconds timeout{2000};  //!< per next() call
  //! Stop after this many consecutive timeouts (0 = never; live sources report kDisconnected).
  int max_consecutive_timeouts = 0;
  //! On kDisconnected: close(), then open() again. This is the budget of open() attempts over
  //! the whole run, not per disconnect, so a source that keeps disconnecting ends (0 = stop
  //! cleanly at the first disconnect).
  int reconnect_attempts = 0;
  std::chrono::milliseconds reconnect_delay{500};
  //! Polled before every read; returning false stops cleanly (SIGINT). Optional.
  std::function<bool()> keep_going;
};

//! \throw OptionError naming the option.
void validate(const AcquisitionOptions& options);

//! Why acquisition (and so run_pipeline) stopped.
enum class StopReason {
  kEndOfStream,
  kFrameLimit,
  kTimeLimit,
  kDisconnected,
  kTimeouts,
  kInterrupted,
  kError
};
const char* to_string(StopReason reason);

struct AcquisitionStats {
  std::uint64_t frames_read = 0;     //!< kOk frames delivered by the source
  std::uint64_t dropped_frames = 0;  //!< missing source indices (sum of index gaps)
  std::uint64_t gap_events = 0;      //!< places where the index jumped by more than 1
  std::uint64_t timeouts = 0;
  std::uint64_t disconnects = 0, reconnects = 0;
  //! Frames lost across reconnects: the index gap when the device kept counting, else estimated
  //! from the host-time gap and the mean frame period.
  std::uint64_t reconnect_lost_frames = 0;
  //! Source indices missing after the last delivered frame (end of stream of a source that
  //! states its frame count); also included in dropped_frames.
  std::uint64_t trailing_dropped_frames = 0;
  bool reconnect_budget_exhausted = false;      //!< stopped: every reconnect attempt was used
  std::uint64_t non_increasing_timestamps = 0;  //!< device timestamps that did not increase
  double seconds_read = 0;                      //!< time spent waiting in next()
  StopReason stop = StopReason::kEndOfStream;
  std::string message;  //!< last_error() for kError / kDisconnected
};

//! Reads `source` (already open) until a stop rule applies and calls on_frame(frame, position)
//! for every delivered frame, in delivery order (position counts from 0; on_frame may move
//! from the frame). It never waits for anything but the source: whatever on_frame does must be
//! quick (hand the frame on). Index gaps and timeouts are counted, never fatal.
//! \throw OptionError (validate) and what the source's open() throws on a reconnect other than
//! UnavailableError, and what on_frame throws.
AcquisitionStats acquire(
    RangeSource& source, const AcquisitionOptions& options,
    const std::function<void(RangeFrame& frame, std::uint64_t position)>& on_frame);

}  // namespace scanclean

#include "scanclean/pipeline/acquisition.h"

#include <chrono>
#include <cmath>
#include <string>
#include <thread>

#include "scanclean/core/errors.h"

namespace scanclean {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

}  // namespace

void validate(const AcquisitionOptions& o) {
  if (o.max_seconds < 0 || !std::isfinite(o.max_seconds))
    throw OptionError("pipeline: option max_seconds = " + std::to_string(o.max_seconds) +
                      " is out of range; valid: >= 0 (0 = no limit)");
  if (o.timeout.count() <= 0)
    throw OptionError("pipeline: option timeout = " + std::to_string(o.timeout.count()) +
                      " ms is out of range; valid: > 0 ms");
  if (o.max_consecutive_timeouts < 0)
    throw OptionError("pipeline: option max_consecutive_timeouts = " +
                      std::to_string(o.max_consecutive_timeouts) + " is out of range; valid: >= 0");
  if (o.reconnect_attempts < 0)
    throw OptionError("pipeline: option reconnect_attempts = " +
                      std::to_string(o.reconnect_attempts) + " is out of range; valid: >= 0");
  if (o.reconnect_delay.count() < 0)
    throw OptionError(
        "pipeline: option reconnect_delay = " + std::to_string(o.reconnect_delay.count()) +
        " ms is out of range; valid: >= 0");
}

const char* to_string(StopReason reason) {
  switch (reason) {
    case StopReason::kEndOfStream:
      return "end of stream";
    case StopReason::kFrameLimit:
      return "frame range done";
    case StopReason::kTimeLimit:
      return "time limit";
    case StopReason::kDisconnected:
      return "disconnected";
    case StopReason::kTimeouts:
      return "too many timeouts";
    case StopReason::kInterrupted:
      return "interrupted";
    case StopReason::kError:
      return "read error";
  }
  return "unknown";
}

AcquisitionStats acquire(RangeSource& source, const AcquisitionOptions& options,
                         const std::function<void(RangeFrame&, std::uint64_t)>& on_frame) {
  validate(options);
  const auto start = Clock::now();
  AcquisitionStats st;
  const SourceInfo info = source.info();
  bool have_last_index = false;
  std::uint64_t last_index = 0;
  bool have_first_index = false, after_reconnect = false;
  std::uint64_t first_index = 0, reconnects_seen = 0;
  int attempts_used = 0;
  std::int64_t last_host_ns = 0;
  double period_sum = 0;
  std::uint64_t period_count = 0;
  std::int64_t last_ts = 0;
  int consecutive_timeouts = 0;
  RangeFrame frame;
  for (;;) {
    if (options.keep_going && !options.keep_going()) {
      st.stop = StopReason::kInterrupted;
      break;
    }
    if (options.max_seconds > 0 && seconds_since(start) >= options.max_seconds) {
      st.stop = StopReason::kTimeLimit;
      break;
    }
    if (options.max_frames != 0 && st.frames_read >= options.max_frames) {
      st.stop = StopReason::kFrameLimit;
      break;
    }
    const auto t_read = Clock::now();
    const ReadStatus status = source.next(frame, options.timeout);
    st.seconds_read += seconds_since(t_read);
    if (status == ReadStatus::kTimeout) {
      ++st.timeouts;
      if (options.max_consecutive_timeouts > 0 &&
          ++consecutive_timeouts >= options.max_consecutive_timeouts) {
        st.stop = StopReason::kTimeouts;
        break;
      }
      continue;
    }
    if (status == ReadStatus::kEndOfStream) {
      st.stop = StopReason::kEndOfStream;
      // Frames dropped after the last one delivered leave no index gap behind them: count them
      // from the source's stated frame count, when the indices seen so far are consistent with
      // it (indices first_index .. first_index + frame_count - 1).
      if (have_first_index && info.frame_count && reconnects_seen == 0) {
        const std::uint64_t expected_last = first_index + *info.frame_count - 1;
        if (*info.frame_count > 0 && expected_last > last_index) {
          st.trailing_dropped_frames = expected_last - last_index;
          st.dropped_frames += st.trailing_dropped_frames;
          ++st.gap_events;
        }
      }
      break;
    }
    if (status == ReadStatus::kError) {
      st.stop = StopReason::kError;
      st.message = source.last_error();
      break;
    }
    if (status == ReadStatus::kDisconnected) {
      ++st.disconnects;
      st.message = source.last_error();
      bool reopened = false;
      while (attempts_used < options.reconnect_attempts && !reopened) {
        ++attempts_used;
        if (options.keep_going && !options.keep_going()) break;
        source.close();
        std::this_thread::sleep_for(options.reconnect_delay);
        try {
          source.open();
          reopened = true;
        } catch (const UnavailableError&) {
          // still gone; try again
        }
      }
      if (!reopened) {
        st.stop = StopReason::kDisconnected;
        if (options.reconnect_attempts > 0 && attempts_used >= options.reconnect_attempts) {
          st.reconnect_budget_exhausted = true;
          st.message = "gave up after " + std::to_string(attempts_used) +
                       " reconnect attempts in total (" + std::to_string(st.disconnects) +
                       " disconnects)" + (st.message.empty() ? "" : "; last: " + st.message);
        }
        break;
      }
      ++st.reconnects;
      ++reconnects_seen;
      after_reconnect = have_last_index;
      have_last_index = false;  // a reopened device may restart its indices
      continue;
    }
    consecutive_timeouts = 0;
    if (!have_first_index) {
      have_first_index = true;
      first_index = frame.index;
    }
    if (after_reconnect) {
      after_reconnect = false;
      if (frame.index > last_index + 1) {
        st.reconnect_lost_frames += frame.index - last_index - 1;  // the device kept counting
      } else if (period_count > 0 && frame.host_ts_ns > last_host_ns) {
        const double period = period_sum / static_cast<double>(period_count);
        const double gap = static_cast<double>(frame.host_ts_ns - last_host_ns);
        if (period > 0 && gap > 1.5 * period)
          st.reconnect_lost_frames += static_cast<std::uint64_t>(std::llround(gap / period)) - 1;
      }
    } else if (have_last_index && frame.host_ts_ns > last_host_ns) {
      period_sum += static_cast<double>(frame.host_ts_ns - last_host_ns);
      ++period_count;
    }
    last_host_ns = frame.host_ts_ns;
    if (have_last_index && frame.index > last_index + 1) {
      st.dropped_frames += frame.index - last_index - 1;
      ++st.gap_events;
    }
    if (have_last_index && frame.device_ts_us <= last_ts) ++st.non_increasing_timestamps;
    have_last_index = true;
    last_index = frame.index;
    last_ts = frame.device_ts_us;
    const std::uint64_t position = st.frames_read++;
    if (on_frame) on_frame(frame, position);
  }
  return st;
}

}  // namespace scanclean

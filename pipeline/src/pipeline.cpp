#include "scanclean/pipeline/pipeline.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "scanclean/core/errors.h"
#include "scanclean/pipeline/accumulate.h"

namespace scanclean {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

}  // namespace

void validate(const PipelineOptions& o) {
  if (o.last_frame != 0 && o.last_frame <= o.first_frame)
    throw OptionError("pipeline: frame range " + std::to_string(o.first_frame) + ":" +
                      std::to_string(o.last_frame) +
                      " is empty; give A:B with B > A (or B empty for 'to the end')");
  if (o.max_seconds < 0)
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
  validate(o.points);
  if (!o.raw) validate(o.filter);
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

PipelineStats run_pipeline(RangeSource& source, const PipelineOptions& options,
                           const std::function<void(WindowOutput&&)>& on_window,
                           bool already_open) {
  validate(options);
  const auto start = Clock::now();
  PipelineStats st;
  if (!already_open) source.open();
  st.info = source.info();

  std::vector<PointCloud> window;
  std::uint64_t window_first = 0;
  auto flush = [&] {
    if (window.empty()) return;
    WindowOutput out;
    out.window = st.windows;
    out.first_frame = window_first;
    out.frames = window.size();
    out.last_frame = window_first + window.size() - 1;
    PointCloud merged;
    std::optional<PointCloud> fused;
    if (!options.raw && options.fuse && window.size() > 1) {
      std::size_t rejected = 0;
      fused = fuse_static_clouds(window, {}, &rejected);
      if (fused) {
        st.fusion_rejected += rejected;
        st.points_fused += fused->size();
        merged = std::move(*fused);
        merged.grid = {};
      }
    }
    if (!fused) merged = accumulate_clouds(window);
    window.clear();
    if (options.raw) {
      out.cloud = std::move(merged);
    } else {
      if (options.keep_input) out.input = merged;
      const auto t = Clock::now();
      FilterResult r = robust_filter(merged, options.filter);
      st.seconds_filter += seconds_since(t);
      st.outliers += r.stats.removed();
      out.cloud = std::move(r.cloud);
      out.outliers = std::move(r.outliers);
      out.filter = r.stats;
    }
    st.points_out += out.cloud.size();
    ++st.windows;
    if (on_window) on_window(std::move(out));
  };

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
  std::uint64_t position = 0;  // delivery position of the next kOk frame
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
    if (options.last_frame != 0 && position >= options.last_frame) {
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
      if (have_first_index && st.info.frame_count && reconnects_seen == 0) {
        const std::uint64_t expected_last = first_index + *st.info.frame_count - 1;
        if (*st.info.frame_count > 0 && expected_last > last_index) {
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
    ++st.frames_read;
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
    const std::uint64_t pos = position++;
    if (pos < options.first_frame) continue;

    const auto t_pts = Clock::now();
    FrameToPointsStats fs;
    PointCloud cloud = frame_to_points(frame, st.info, options.points, &fs);
    st.seconds_points += seconds_since(t_pts);
    st.edge_dropped += fs.edge_dropped;
    st.out_of_range += fs.out_of_range;
    st.no_normal += fs.no_normal;
    st.points_in += cloud.size();
    if (st.frames_used == 0) {
      st.min_points_per_frame = st.max_points_per_frame = cloud.size();
    } else {
      st.min_points_per_frame = std::min(st.min_points_per_frame, cloud.size());
      st.max_points_per_frame = std::max(st.max_points_per_frame, cloud.size());
    }
    ++st.frames_used;
    if (window.empty()) window_first = pos;
    window.push_back(std::move(cloud));
    if (options.on_frame) options.on_frame(st.frames_used);
    if (options.accumulate > 0 && window.size() >= options.accumulate) flush();
  }
  flush();  // the last (possibly partial) window: nothing read is lost
  st.seconds_total = seconds_since(start);
  return st;
}

}  // namespace scanclean

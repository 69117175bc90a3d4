#pragma once
//! \file pipeline.h
//! The capture-and-clean runner: pulls frames from any RangeSource (it never knows which),
//! converts them to points, groups them in windows of N frames and cleans each window with the
//! robust filter. Used by `scanclean replay` and `scanclean capture`.

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "scanclean/core/point_cloud.h"
#include "scanclean/core/range_source.h"
#include "scanclean/filter/robust_filter.h"
#include "scanclean/pipeline/frame_to_points.h"

namespace scanclean {

struct PipelineOptions {
  //! Delivered frames [first_frame, last_frame) are used, counted from 0 in delivery order
  //! (not by source index); frames before first_frame are read and skipped. last_frame 0 = to
  //! the end.
  std::uint64_t first_frame = 0;
  std::uint64_t last_frame = 0;
  //! Frames per output window (each window filtered into one cloud); 0 = all frames in one.
  std::size_t accumulate = 0;
  double max_seconds = 0;                   //!< stop after this much wall time (0 = no limit)
  std::chrono::milliseconds timeout{2000};  //!< per next() call
  //! Stop after this many consecutive timeouts (0 = never; live sources report kDisconnected).
  int max_consecutive_timeouts = 0;
  //! On kDisconnected: close(), then open() again. This is the budget of open() attempts over
  //! the whole run, not per disconnect, so a source that keeps disconnecting ends (0 = stop
  //! cleanly at the first disconnect).
  int reconnect_attempts = 0;
  std::chrono::milliseconds reconnect_delay{500};
  bool raw = false;  //!< no filter: each window's points are the output (normals, confidences)
  //! Before filtering, fuse each window's frames per pixel (fuse_static_clouds: one static
  //! view, as accumulation assumes): one point per pixel with the temporal mean of its
  //! consistent samples, weighted by how many there are. false: every sample is a point.
  bool fuse = true;
  FrameToPointsOptions points;
  FilterOptions filter;
  //! Keep each window's points as they went into the filter in WindowOutput::input (e.g. for a
  //! before/after preview).
  bool keep_input = false;
  //! Polled before every read; returning false stops cleanly (SIGINT). Optional.
  std::function<bool()> keep_going;
  //! Called after each used frame (frames used so far). Optional.
  std::function<void(std::uint64_t)> on_frame;
};

//! \throw OptionError naming the option (also validates points and, unless raw, filter).
void validate(const PipelineOptions& options);

//! Why run_pipeline stopped.
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

//! One output cloud: the frames [first, last] of the window (delivery positions).
struct WindowOutput {
  std::size_t window = 0;
  std::uint64_t first_frame = 0, last_frame = 0;
  std::size_t frames = 0;
  PointCloud cloud;     //!< cleaned (or raw) points
  PointCloud outliers;  //!< points the filter removed (empty when raw)
  FilterStats filter;   //!< zero when raw
  PointCloud input;     //!< the filter's input, only with PipelineOptions::keep_input
};

struct PipelineStats {
  std::uint64_t frames_read = 0;     //!< kOk frames delivered by the source (skipped ones too)
  std::uint64_t frames_used = 0;     //!< frames in [first_frame, last_frame) converted
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
  std::size_t windows = 0;
  std::size_t points_in = 0;        //!< points from frame_to_points over all used frames
  std::size_t points_out = 0;       //!< points in all outputs
  std::size_t outliers = 0;         //!< points the filter removed (FilterStats::removed())
  std::size_t points_fused = 0;     //!< points the per-pixel fusion made (input to the filter)
  std::size_t fusion_rejected = 0;  //!< samples the fusion dropped (off the pixel's median)
  std::size_t edge_dropped = 0, out_of_range = 0, no_normal = 0;
  std::size_t min_points_per_frame = 0, max_points_per_frame = 0;
  double seconds_read = 0, seconds_points = 0, seconds_filter = 0, seconds_total = 0;
  StopReason stop = StopReason::kEndOfStream;
  std::string message;  //!< last_error() for kError / kDisconnected
  SourceInfo info;      //!< the source's info after open()
};

//! Opens `source` (unless `already_open`), reads frames until the end of the stream, the frame
//! range or time limit, a disconnect (after the reconnect attempts), too many timeouts,
//! keep_going() == false or kError, and delivers each window to `on_window` in order (the
//! last, possibly partial window too: nothing read is lost). Frames are processed in order and
//! the filter is deterministic, so outputs do not depend on thread counts. Index gaps and
//! timeouts are counted, never fatal. \throw OptionError (validate) and what open(),
//! frame_to_points or robust_filter throw (InputError, UnavailableError, ...).
PipelineStats run_pipeline(RangeSource& source, const PipelineOptions& options,
                           const std::function<void(WindowOutput&&)>& on_window,
                           bool already_open = false);

}  // namespace scanclean

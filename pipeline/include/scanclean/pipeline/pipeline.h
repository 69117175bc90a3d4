#pragma once
//! \file pipeline.h
//! The capture-and-clean runner: pulls frames from any RangeSource (it never knows which),
//! groups them in windows of N frames and cleans each window (clean_window.h). Used by
//! `scanclean replay` and `scanclean capture`.
//!
//! Stages (a oneTBB flow graph, joined by queues): acquisition (acquire(), in the calling
//! thread) only drains the source at its own rate, records every frame (`record`) and collects
//! the frames of the current window; conversion + per-pixel fusion (window_input); the filter
//! (clean_window_input); the output (on_window). Windows stay
//! in order and the filter is deterministic, so outputs do not depend on thread counts.
//! Complete windows wait for cleaning within memory_budget_bytes; beyond it, a device source's
//! window is skipped for cleaning (counted and listed in PipelineStats::skipped; a recording
//! still holds its frames), while a file source's acquisition waits (files never skip).

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "scanclean/core/point_cloud.h"
#include "scanclean/core/range_source.h"
#include "scanclean/filter/robust_filter.h"
#include "scanclean/pipeline/acquisition.h"
#include "scanclean/pipeline/clean_window.h"
#include "scanclean/pipeline/frame_to_points.h"

namespace scanclean {

struct PipelineOptions {
  //! Delivered frames [first_frame, acquisition.max_frames) are used, counted from 0 in
  //! delivery order (not by source index); frames before first_frame are read and skipped.
  //! acquisition.max_frames 0 = to the end.
  std::uint64_t first_frame = 0;
  //! Frames per output window (each window filtered into one cloud); 0 = all frames in one.
  std::size_t accumulate = 0;
  //! How frames are read: the frame limit, seconds, timeouts, reconnects, keep_going (Ctrl-C).
  AcquisitionOptions acquisition;
  //! How each window is cleaned: conversion, per-pixel fusion, raw, the filter (the depth-frame
  //! preset) and keep_input (each window's filter input kept in WindowOutput::input, e.g. for a
  //! before/after preview).
  WindowOptions window;
  //! Complete windows waiting to be cleaned (their raw frames, from the moment the window is
  //! complete until its output is delivered) may hold at most this many bytes; a window that
  //! would exceed it while others wait is skipped (device sources) or waited for (files). A
  //! window alone is always accepted. > 0. Default 128 MiB: 7 windows of 30 VGA frames (the
  //! latency of a cleaned window grows with the windows waiting before it).
  std::size_t memory_budget_bytes = std::size_t{128} << 20;
  //! Whether a window beyond the budget is skipped. kAuto: skip for device sources (SourceInfo
  //! kind "openni2" or "vsensor", which pace themselves), wait for every other (file) source.
  enum class Backlog { kAuto, kSkip, kWait } backlog = Backlog::kAuto;
  //! Records every delivered frame (frames before first_frame too), in delivery order, in the
  //! acquisition stage itself (this thread, never behind a cleaning task: TBB workers run those).
  //! A source that emits frames on its own clock must keep them while this runs (OpenNI2
  //! devices do, drivers/openni2). Optional.
  std::function<void(const SourceInfo& info, const RangeFrame& frame)> record;
  //! Called after each used frame (frames used so far), from the calling thread. Optional.
  std::function<void(std::uint64_t)> on_frame;
  //! Called when a window starts (true) or ends (false) its filter, from a worker thread, one
  //! call at a time. Optional (progress displays).
  std::function<void(std::size_t window, bool starts)> on_cleaning;
  //! Called with a window's number just before it is fused and filtered, from a worker thread,
  //! one window at a time, in order. Optional (tests: a slow cleaning stage).
  std::function<void(std::size_t window)> before_cleaning;
};

//! \throw OptionError naming the option (also validates the acquisition and window options).
void validate(const PipelineOptions& options);

//! One output cloud: the frames [first, last] of the window (delivery positions).
struct WindowOutput {
  std::size_t window = 0;
  std::uint64_t first_frame = 0, last_frame = 0;
  std::size_t frames = 0;
  PointCloud cloud;     //!< cleaned (or raw) points
  PointCloud outliers;  //!< points the filter removed (empty when raw)
  FilterStats filter;   //!< zero when raw
  PointCloud input;     //!< the filter's input, only with PipelineOptions::window.keep_input
};

//! A window that was not cleaned because cleaning fell behind (memory budget).
struct SkippedWindow {
  std::size_t window = 0;
  std::uint64_t first_frame = 0, last_frame = 0;  //!< delivery positions
  std::uint64_t first_index = 0, last_index = 0;  //!< source frame indices
};

//! The acquisition's counts (frames_read, gaps, timeouts, reconnects, stop, ...) plus the
//! windows'.
struct PipelineStats : AcquisitionStats {
  std::uint64_t frames_used =
      0;  //!< frames in [first_frame, acquisition.max_frames) put in windows
  std::uint64_t frames_cleaned = 0;  //!< frames of the windows that were output
  std::size_t windows = 0;
  std::size_t points_in = 0;   //!< valid samples (fused windows) or points (others) of used frames
  std::size_t points_out = 0;  //!< points in all outputs
  std::size_t outliers = 0;    //!< points the filter removed (FilterStats::removed())
  std::size_t points_fused = 0;     //!< points the per-pixel fusion made (input to the filter)
  std::size_t fusion_rejected = 0;  //!< samples the fusion dropped (off the pixel's median)
  std::size_t edge_dropped = 0, out_of_range = 0, no_normal = 0;
  std::size_t min_points_per_frame = 0, max_points_per_frame = 0;
  double seconds_points = 0, seconds_filter = 0, seconds_total = 0;
  std::vector<SkippedWindow> skipped;  //!< windows skipped for cleaning, in order
  //! Latency from a frame's arrival (its delivery by next()) to its window's output (on_window
  //! returned), over the frames of output windows: median and 95th percentile, seconds.
  double latency_p50_s = 0, latency_p95_s = 0;
  std::size_t peak_waiting_bytes = 0;  //!< most bytes of complete windows waiting at once
  std::uint64_t frames_recorded = 0;   //!< frames `record` wrote
  SourceInfo info;                     //!< the source's info after open()
};

//! Opens `source` (unless `already_open`) and closes it when acquisition ends (before the
//! backlog is cleaned), reads frames (acquire()) until the end of the
//! stream, the frame range or time limit, a disconnect (after the reconnect attempts), too many
//! timeouts, keep_going() == false or kError, and delivers each cleaned window to `on_window` in
//! order (the last, possibly partial window too: it is never skipped), from a worker thread, one
//! window at a time. Windows are numbered by position (window k holds positions first_frame +
//! k N ..), skipped ones included, so a replay of a recording numbers them alike. Index gaps and
//! timeouts are counted, never fatal. \throw OptionError (validate) and what open(),
//! frame_to_points or robust_filter throw (InputError, UnavailableError, ...).
PipelineStats run_pipeline(RangeSource& source, const PipelineOptions& options,
                           const std::function<void(WindowOutput&&)>& on_window,
                           bool already_open = false);

}  // namespace scanclean

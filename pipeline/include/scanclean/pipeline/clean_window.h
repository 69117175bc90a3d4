#pragma once
//! \file clean_window.h
//! The one path from a window of range frames to a cleaned cloud, used by the capture-and-clean
//! runner (pipeline.h), the program and the tests: frame_to_points on every frame, per-pixel
//! fusion of the static view (fuse_static_clouds), then the robust filter with the depth-frame
//! preset (depth_frame_options()). Two steps, so that a pipeline can run them as separate
//! stages: window_input (conversion + fusion) and clean_window_input (the filter).

#include <cstddef>
#include <vector>

#include "scanclean/core/point_cloud.h"
#include "scanclean/core/range_frame.h"
#include "scanclean/core/range_source.h"
#include "scanclean/filter/filter_options.h"
#include "scanclean/filter/robust_filter.h"
#include "scanclean/pipeline/accumulate.h"
#include "scanclean/pipeline/frame_to_points.h"

namespace scanclean {

//! How a window of frames is cleaned. The defaults are what `replay` and `capture` run.
struct WindowOptions {
  FrameToPointsOptions points;
  //! Fuse the window's frames per pixel before filtering (one static view, as accumulation
  //! assumes); false, or frames of different sizes: every sample is a point.
  bool fuse = true;
  //! Fuse the depth images per pixel (the same rule) and convert the fused depth once, instead
  //! of converting every frame and fusing the clouds: normals and flying pixels come from the
  //! fused depth. Frames with a points image or sensor normals, or of different sizes or
  //! intrinsics, are fused as clouds. When every frame carries a colour image of the depth's
  //! size, a fused pixel's colour is the mean (per channel, rounded) of the colours of the
  //! samples the fusion kept; frames of which only some carry colour are fused as clouds.
  bool fuse_depth = true;
  FuseOptions fusion;
  bool raw = false;  //!< no filter: the window's points (appended, not fused) are the output
  FilterOptions filter = depth_frame_options();  //!< the depth-frame preset
  bool keep_input = false;  //!< keep the filter's input in WindowResult::input (previews)
};

//! \throw OptionError naming the option (points, fusion and, unless raw, filter).
void validate(const WindowOptions& options);

//! The filter's input for one window, with the conversion's counts.
struct WindowInput {
  PointCloud cloud;  //!< fused (organized grid kept) or appended (unorganized) points
  std::size_t frames = 0;
  std::size_t points_in = 0;  //!< points frame_to_points made over the window's frames
  std::size_t min_points_per_frame = 0, max_points_per_frame = 0;
  std::size_t edge_dropped = 0, out_of_range = 0, no_normal = 0;
  std::size_t points_fused = 0;     //!< points of the fused cloud (0 when not fused)
  std::size_t fusion_rejected = 0;  //!< samples the fusion dropped (off the pixel's median)
  double seconds_points = 0;        //!< conversion + fusion wall time
};

//! One cleaned window.
struct WindowResult {
  PointCloud cloud;     //!< cleaned (or raw) points
  PointCloud outliers;  //!< points the filter removed (empty when raw)
  FilterStats filter;   //!< zero when raw
  PointCloud input;     //!< the filter's input, only with WindowOptions::keep_input
  double seconds_filter = 0;
};

//! Step 1: frame_to_points on every frame (in parallel; the result does not depend on the
//! thread count), then per-pixel fusion when options.fuse, !options.raw and more than one frame
//! of one grid size; else the frames' points appended. \throw as frame_to_points.
WindowInput window_input(const std::vector<RangeFrame>& frames, const SourceInfo& info,
                         const WindowOptions& options);

//! Step 2: robust_filter (input normals = sensor normals, confidences = weights), or the points
//! unchanged when options.raw. Deterministic for any filter thread count. \throw as
//! robust_filter.
WindowResult clean_window_input(WindowInput&& input, const WindowOptions& options);

//! Both steps: the window path of the program. \throw as window_input and clean_window_input.
WindowResult clean_window(const std::vector<RangeFrame>& frames, const SourceInfo& info,
                          const WindowOptions& options = {});

}  // namespace scanclean

#pragma once
//! \file accumulate.h
//! Multi-frame capture-and-clean of a static scene: several frames become one cloud, which the
//! robust filter cleans; plus a per-pixel temporal-noise analysis for tests and reports.

#include <cstddef>
#include <vector>

#include "scanclean/core/image.h"
#include "scanclean/core/point_cloud.h"
#include "scanclean/core/range_frame.h"
#include "scanclean/core/range_source.h"
#include "scanclean/filter/robust_filter.h"
#include "scanclean/pipeline/frame_to_points.h"

namespace scanclean {

//! The frames' clouds appended in order (unorganized; normals and confidences kept).
PointCloud accumulate_clouds(const std::vector<PointCloud>& clouds);

//! frame_to_points on every frame, appended, then robust_filter (input normals = sensor normals,
//! confidences = weights). Deterministic for any filter thread count.
//! \throw as frame_to_points and robust_filter.
FilterResult accumulate_and_clean(const std::vector<RangeFrame>& frames, const SourceInfo& info,
                                  const FrameToPointsOptions& points_options = {},
                                  const FilterOptions& filter_options = {});

//! Per-pixel temporal statistics of the depth (metres) over frames of one static view.
struct TemporalSpread {
  int width = 0, height = 0;
  Image<float> mean_m;               //!< per-pixel mean depth over the frames where it is valid
  Image<float> std_m;                //!< per-pixel population standard deviation (metres)
  Image<std::uint16_t> valid_count;  //!< frames in which the pixel is valid
  std::size_t frames = 0;
  std::size_t pixels_valid_in_all = 0;  //!< pixels valid in every frame
  double mean_std_m = 0;                //!< mean of std_m over pixels valid in every frame
  double median_std_m = 0;              //!< median of the same
};

//! Per-pixel depth spread across `frames` (all of one size; depth x depth_unit_m; 0 = invalid).
//! \throw InputError when the frames differ in size or there are none.
TemporalSpread temporal_depth_spread(const std::vector<RangeFrame>& frames);

}  // namespace scanclean

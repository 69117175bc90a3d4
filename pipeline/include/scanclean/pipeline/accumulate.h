#pragma once
//! \file accumulate.h
//! Multi-frame accumulation of a static scene: several frames become one cloud (appended or
//! fused per pixel; clean_window.h cleans it), plus a per-pixel temporal-noise analysis for tests
//! and reports.

#include <cstddef>
#include <optional>
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

struct FuseOptions {
  //! Samples farther from the pixel's median depth than this fraction of it are dropped
  //! (flying pixels, flicker to the background), (0, 1]. 0.02 keeps the neighbouring
  //! quantisation levels of a PS1080 up to its 10 m range (step 2.9e-3 z^2 < 0.02 z), so their
  //! dither averages out.
  double max_depth_deviation_factor = 0.02;
};

//! Per-pixel temporal fusion of the organized clouds of one static view (as frame_to_points
//! makes them, all with the same grid size): each pixel's samples within
//! max_depth_deviation_factor x z of their median depth are averaged (position, normal), and
//! the fused point's confidence is mean(confidence) x kept / frames (inverse-variance weights:
//! the mean of n samples has 1/n of the variance; pixels seen in few frames weigh less).
//! Output: one organized cloud of the same grid, pixels in row-major order. Returns nullopt when
//! the clouds are not all organized with one grid size (then use accumulate_clouds).
//! \p rejected, if given, receives the number of samples dropped by the depth test.
std::optional<PointCloud> fuse_static_clouds(const std::vector<PointCloud>& clouds,
                                             const FuseOptions& options = {},
                                             std::size_t* rejected = nullptr);

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

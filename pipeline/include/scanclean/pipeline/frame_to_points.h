#pragma once
//! \file frame_to_points.h
//! One range frame to an organized point cloud with sensor normals and confidence weights
//! (docs/SENSORS.md §4). Camera frame (OpenCV: x right, y down, z forward), metres.

#include <Eigen/Core>
#include <cstddef>
#include <string>

#include "scanclean/core/point_cloud.h"
#include "scanclean/core/range_frame.h"
#include "scanclean/core/range_source.h"

namespace scanclean {

struct FrameToPointsOptions {
  //! Half-width s of the normal stencil (pixels), [1, 32]. s = 2-3 is accurate on PS1080 data.
  int normal_stencil = 2;
  //! A stencil neighbour whose depth differs from the centre's by more than this fraction of
  //! the centre depth gives no normal; also the depth-discontinuity test. (0, 1].
  double max_depth_change_factor = 0.02;
  //! Pixels within this many pixels of a depth discontinuity (a jump > factor x z between two
  //! valid 4-neighbours) are flying-pixel suspects: weight 0, dropped and counted. 0 = off;
  //! m >= 1 drops the two pixels at the jump and m - 1 more on each side. [0, 32].
  int edge_margin_px = 2;
  double min_depth_m = 0;  //!< drop points nearer than this (0 = no limit), >= 0
  double max_depth_m = 0;  //!< drop points farther than this (0 = no limit), >= 0
  //! Noise-model weights. false: every confidence is 1 (times the frame's confidence image).
  bool weights = true;
  //! "" = SourceInfo::noise_model; else "nguyen2012", "structured-light" or "none". Only
  //! "nguyen2012" computes depth-dependent weights; the others give 1 x frame confidence.
  std::string noise_model;
};

//! \throw OptionError naming the option, the value and the valid range.
void validate(const FrameToPointsOptions& options);

//! Pixel counts of one conversion.
struct FrameToPointsStats {
  std::size_t pixels = 0;        //!< width x height
  std::size_t valid = 0;         //!< pixels with a depth (or a finite point)
  std::size_t out_of_range = 0;  //!< valid pixels outside [min_depth_m, max_depth_m]
  std::size_t edge_dropped = 0;  //!< valid pixels dropped near depth discontinuities
  std::size_t zero_weight = 0;   //!< dropped because the frame confidence was 0
  std::size_t no_normal = 0;     //!< kept points without a normal (normal stored as 0)
  std::size_t points = 0;        //!< output points
};

//! Back-projects every valid pixel: P = z (x, y, 1) with (x, y) the undistorted normalized
//! coordinates of the pixel under frame.K (pinhole plus OpenCV k1 k2 p1 p2 k3, undistorted
//! iteratively), z = depth x depth_unit_m; or the frame's `points` image when present (NaN or
//! z <= 0 = invalid). Normals: the frame's sensor_normals when present and non-zero, else
//! n = normalize((P(u+s,v) - P(u-s,v)) x (P(u,v-s) - P(u,v+s))) flipped to face the sensor
//! (n . P < 0); zero (unknown) when a stencil neighbour is invalid, off the image or differs
//! by more than max_depth_change_factor x z. Confidences: nguyen_weight(z, theta) with
//! cos theta = |n . P/|P|| (theta = 0 without a normal) for the "nguyen2012" model, else 1;
//! times the frame's confidence image (clamped to [0, 1]); points of weight 0 are dropped.
//! Output: points in row-major pixel order, grid rows = height, cols = width (-1 = no point).
//! \throw OptionError (validate), InputError when the frame is malformed (image sizes differ
//! from each other, no depth and no points, depth_unit_m <= 0, K missing for depth frames).
//! Thread-safe (pure function).
PointCloud frame_to_points(const RangeFrame& frame, const SourceInfo& info,
                           const FrameToPointsOptions& options = {},
                           FrameToPointsStats* stats = nullptr);

//! The normalized ray direction (x, y, 1) of pixel (u, v) under K, with the distortion removed
//! (fixed-point iteration as OpenCV's undistortPoints; exact for no distortion).
Eigen::Vector2d undistort_pixel(const Intrinsics& K, double u, double v);

//! The pixel where the camera-frame point P (z > 0) projects under K, distortion applied.
Eigen::Vector2d project_point(const Intrinsics& K, const Eigen::Vector3d& P);

}  // namespace scanclean

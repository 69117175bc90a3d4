#pragma once
// Private: the camera model of an Intrinsics (core/range_frame.h) as OpenCV's matrices, for the
// structured-light code that calls OpenCV (triangulation, board measurement, calib.yml).

#include <opencv2/core.hpp>

#include "scanclean/core/range_frame.h"

namespace scanclean::sl_detail {

//! The 3x3 camera matrix [fx 0 cx; 0 fy cy; 0 0 1] (CV_64F).
inline cv::Mat camera_matrix(const Intrinsics& k) {
  return (cv::Mat_<double>(3, 3) << k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1);
}

//! The distortion row (k1, k2, p1, p2, k3) in OpenCV's order (CV_64F).
inline cv::Mat dist_coeffs(const Intrinsics& k) {
  return (cv::Mat_<double>(1, 5) << k.dist[0], k.dist[1], k.dist[2], k.dist[3], k.dist[4]);
}

}  // namespace scanclean::sl_detail

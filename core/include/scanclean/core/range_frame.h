#pragma once
//! \file range_frame.h
//! One frame of a range sensor, as every RangeSource delivers it.
//! Camera coordinates follow OpenCV: x right, y down, z forward (along the optical axis), metres.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <optional>
#include <string>

#include "scanclean/core/image.h"

namespace scanclean {

//! Pinhole intrinsics with OpenCV's (k1 k2 p1 p2 k3) distortion, in pixels.
struct Intrinsics {
  double fx = 0, fy = 0, cx = 0, cy = 0;
  std::array<double, 5> dist{};  //!< k1 k2 p1 p2 k3; all zero = no distortion
  int width = 0, height = 0;
  std::string source = "fov";  //!< "fov" (nominal, from the field of view) or "calibration"

  bool valid() const { return fx > 0 && fy > 0 && width > 0 && height > 0; }
  bool has_distortion() const;
  //! The model OpenNI's CoordinateConverter uses: fx = W / (2 tan(hfov/2)), principal point at
  //! (W/2, H/2), no distortion. Throws OptionError for non-positive sizes or angles.
  static Intrinsics from_fov(int width, int height, double hfov_rad, double vfov_rad);
};

//! Nominal PrimeSense PS1080 constants (docs/SENSORS.md §4), used by the quantisation noise model.
struct Ps1080Params {
  double zpd_mm = 0;       //!< zero-plane distance
  double zpps_mm = 0;      //!< zero-plane pixel size
  double lddis_cm = 0;     //!< emitter to depth-camera distance (baseline)
  double param_coeff = 0;  //!< disparity sub-pixel coefficient
};

struct RangeFrame {
  std::uint64_t index = 0;        //!< source frame index; a gap means dropped frames
  std::int64_t device_ts_us = 0;  //!< device timestamp (microseconds)
  std::int64_t host_ts_ns = 0;    //!< host receive time (steady clock, nanoseconds)

  Image<std::uint16_t> depth;  //!< 0 = invalid; metres = value * depth_unit_m
  double depth_unit_m = 0.001;
  Intrinsics K;

  //! Optional organized 3-D points (camera frame, metres, NaN = invalid) when the source knows
  //! them more precisely than depth + K (structured-light triangulation with distortion).
  std::optional<Image<Eigen::Vector3f>> points;
  //! Optional per-pixel confidence in [0, 1] (e.g. the structured-light decode confidence).
  std::optional<Image<float>> confidence;
  //! Optional per-pixel sensor normals (unit, facing the sensor; zero = unknown).
  std::optional<Image<Eigen::Vector3f>> sensor_normals;
  //! Optional per-pixel colour (RGB) registered to the depth pixels (same size); the points
  //! made from the frame carry it.
  std::optional<Image<std::array<std::uint8_t, 3>>> color;

  int width() const { return points ? points->width : depth.width; }
  int height() const { return points ? points->height : depth.height; }
};

}  // namespace scanclean

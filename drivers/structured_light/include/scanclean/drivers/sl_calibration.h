#pragma once
//! \file sl_calibration.h
//! Camera-projector calibration of a structured-light rig (docs/SENSORS.md §5, §8).
//! Two file layouts are read, detected by content:
//!  - the project's calib.yml (cv::FileStorage YAML/XML): cam_K, cam_dist, proj_K, proj_dist,
//!    R, T, cam_size [w, h], proj_size [w, h], units ("mm" or "m"), rms;
//!  - kamino410/procam-calibration's calibration_result.xml: cam_int, cam_dist, proj_int,
//!    proj_dist, roration [sic], translation, img_shape [rows, cols], rms. It carries no unit and
//!    no projector size: the unit is assumed to be millimetres (the chessboard square size of the
//!    calibration, 75 in the repository's example command), stated by unit_assumed.
//! Extrinsics: X_p = R X_c + T (camera to projector, as cv::stereoCalibrate returns them).

#include <Eigen/Core>
#include <filesystem>
#include <string>
#include <string_view>

#include "scanclean/core/range_frame.h"

namespace scanclean {

struct SlCalibration {
  Intrinsics camera;     //!< pixels; width/height = camera image size; source "calibration"
  Intrinsics projector;  //!< pixels; width/height = projector size, 0 when the file has none
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  //!< camera -> projector rotation
  Eigen::Vector3d T = Eigen::Vector3d::Zero();      //!< camera -> projector translation (unit_m)
  double unit_m = 0.001;                            //!< metres per calibration length unit (T)
  bool unit_assumed = false;  //!< true when the file states no unit (kamino410: mm assumed)
  double rms = 0;             //!< calibration RMS reprojection error (pixels), 0 if absent
  //! Decoded Gray-code pixel k is projector pixel graycode_step * k (kamino410's graycode_step:
  //! patterns generated for a projector size / step and enlarged step times). calib.yml field
  //! "graycode_step" (optional, default 1).
  int graycode_step = 1;
  std::string layout;          //!< "scanclean" (calib.yml) or "kamino410"
  std::filesystem::path file;  //!< where it was read from (empty if built in memory)
};

//! Parses calibration text (either layout; YAML or XML as cv::FileStorage writes them) from a
//! byte buffer, with a strict reader of its own: OpenCV's FileStorage parser is not given
//! untrusted bytes (it crashes, loops or allocates without bound on small malformed files).
//! At most 1 MiB of printable ASCII; matrices up to 16x16 with rows x cols values; every number
//! finite. `name` labels the errors (a file name). JSON is not read.
//! \throw InputError naming `name`, the line and what was expected.
SlCalibration parse_sl_calibration(std::string_view text, const std::string& name);

//! Reads a calibration file (either layout, detected from the field names).
//! \throw InputError naming the file and the missing or malformed field (a matrix of the wrong
//! size, a non-positive focal length, a non-rotation R, an unknown unit); IoError if unreadable.
SlCalibration read_sl_calibration(const std::filesystem::path& file);

//! Writes the project's calib.yml layout (atomically). \throw IoError.
void write_sl_calibration(const std::filesystem::path& file, const SlCalibration& calibration);

//! Writes kamino410/procam-calibration's calibration_result.xml layout (atomically): the
//! translation in millimetres (that layout's assumed unit), img_shape [rows, cols].
//! \throw IoError.
void write_sl_calibration_kamino(const std::filesystem::path& file,
                                 const SlCalibration& calibration);

}  // namespace scanclean

#pragma once
//! \file sl_board.h
//! The chessboard target of a structured-light rig: its inner corners in the camera (OpenCV
//! findChessboardCorners + cornerSubPix on the white image), each corner's projector coordinate
//! through a local homography fitted to the decoded pixels around it (Moreno and Taubin 2012,
//! "Simple, accurate, and robust projector-camera calibration"), and flatness / size
//! measurements of the reconstructed board (`sl decode --fit-plane`, `sl calibrate`).

#include <Eigen/Core>
#include <cstddef>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "scanclean/drivers/sl_calibration.h"
#include "scanclean/drivers/sl_capture.h"
#include "scanclean/drivers/sl_decode.h"

namespace scanclean {

//! A printed chessboard: inner corners per row (cols) and per column (rows), square side.
struct SlChessboard {
  int cols = 9;             //!< inner corners along a row, >= 2
  int rows = 7;             //!< inner corners along a column, >= 2
  double square_m = 0.075;  //!< square side (metres), > 0
};
//! \throw OptionError naming the option, the value and the valid range.
void validate(const SlChessboard& board);
//! "9x7" -> cols 9, rows 7. \throw OptionError.
void parse_chessboard_size(const std::string& text, SlChessboard& board);

struct SlCornerOptions {
  int window_radius_px = 20;      //!< local homography window: (2 r + 1)^2 camera pixels, >= 3
  int min_support = 40;           //!< decoded pixels needed in a window, >= 8
  double ransac_threshold = 1.0;  //!< decoded projector pixels, > 0
};
//! \throw OptionError.
void validate(const SlCornerOptions& options);

struct SlBoardCorners {
  bool found = false;                      //!< the chessboard was found in the white image
  std::vector<Eigen::Vector2d> camera;     //!< camera pixels, OpenCV order (cols x rows)
  std::vector<Eigen::Vector2d> projector;  //!< decoded projector coordinates; NaN: no decode
  std::vector<int> support;                //!< decoded pixels used per corner
  std::size_t projector_found() const;     //!< corners with a projector coordinate
};

//! Finds the board's inner corners in the capture's white image and maps each into the
//! projector through a robust local homography (cv::findHomography, RANSAC) from the decoded
//! pixels in its window (sub-stripe coordinates when decoded, else integer ones) to projector
//! coordinates. Returns found = false when OpenCV does not find the board.
SlBoardCorners find_sl_board_corners(const SlCapture& capture, const SlDecoded& decoded,
                                     const SlChessboard& board,
                                     const SlCornerOptions& options = {});

//! Plane-residual statistics of points in a region of the board.
struct SlPlaneStats {
  std::size_t points = 0;  //!< points in the region
  double rms_m = 0;        //!< RMS distance to the plane over every point of the region
  double p95_m = 0;        //!< 95th percentile of |distance|
  double inliers = 0;      //!< fraction within the fit band
};

struct SlBoardMeasureOptions {
  SlChessboard board;
  double window_m = 0.30;  //!< central window side (metres, along the board axes), > 0
  double band_m = 0.010;   //!< robust plane fit inlier band (metres), > 0
};
//! \throw OptionError.
void validate(const SlBoardMeasureOptions& options);

//! The board's region: homography from normalised undistorted camera coordinates (x/z, y/z) to
//! board coordinates (metres, origin at the first inner corner), built from the corners.
//! "Whole board" = inside the inner-corner grid ((cols-1) x (rows-1) squares), "central window"
//! = a window_m square centred on the grid centre.
class SlBoardRegion {
 public:
  //! \throw InputError (location `where`) when the corners are not found or degenerate.
  SlBoardRegion(const SlBoardCorners& corners, const SlCalibration& calibration,
                const SlBoardMeasureOptions& options, const std::string& where);
  //! Board coordinates (metres) of a camera-frame point.
  Eigen::Vector2d board_xy(const Eigen::Vector3d& p) const;
  bool in_board(const Eigen::Vector3d& p) const;
  bool in_window(const Eigen::Vector3d& p) const;

 private:
  Eigen::Matrix3d H_;
  double width_m_, height_m_, half_window_m_;
};

struct SlBoardMeasurement {
  SlPlaneStats board;                                 //!< whole board, own plane fit
  SlPlaneStats window;                                //!< central window, own plane fit
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  //!< whole-board plane (camera frame)
  double offset = 0;                                  //!< plane: normal . x + offset = 0
};

//! Robust plane fit (fit_plane_robust, band options.band_m, seeded) of the points of each region,
//! then RMS and 95th percentile of |distance| over every point of the region.
//! \throw InputError (location `where`) when a region has fewer than 100 points.
SlBoardMeasurement measure_sl_board(const std::vector<Eigen::Vector3d>& points,
                                    const SlBoardRegion& region,
                                    const SlBoardMeasureOptions& options, const std::string& where);

//! Square size from the triangulated corners: mean and standard deviation of the distances
//! between neighbouring corners (metres) and how many distances were used.
struct SlSquareSize {
  double mean_m = 0;
  double std_m = 0;
  int count = 0;
};
SlSquareSize measure_sl_squares(const SlBoardCorners& corners, const SlCalibration& calibration,
                                const SlChessboard& board);

//! Writes a residual map (8-bit colour PNG, atomically): every point of the board region drawn at
//! its camera pixel, coloured by its signed distance to `plane` (blue -range .. red +range,
//! metres), cropped to the board with a margin; black where no point.
//! \throw IoError when the file cannot be written.
void write_sl_residual_map(const std::filesystem::path& file,
                           const std::vector<Eigen::Vector3d>& points,
                           const SlBoardMeasurement& plane, const SlBoardRegion& region,
                           const SlCalibration& calibration, double range_m);

}  // namespace scanclean

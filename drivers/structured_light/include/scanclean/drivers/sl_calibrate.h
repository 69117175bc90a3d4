#pragma once
//! \file sl_calibrate.h
//! Camera-projector calibration from chessboard captures under the Gray-code sequence (the
//! method of Moreno and Taubin 2012): per capture the board's inner corners in the camera and,
//! through local homographies of the decoded pixels, in the projector (sl_board.h); then
//! cv::calibrateCamera for the camera and for the projector, and cv::stereoCalibrate (intrinsics
//! fixed) for the camera -> projector pose. The projector is modelled at the decoded Gray-code
//! resolution (graycode_step 1): projector pixel = decoded coordinate.

#include <string>
#include <vector>

#include "scanclean/drivers/sl_board.h"
#include "scanclean/drivers/sl_calibration.h"
#include "scanclean/drivers/sl_capture.h"
#include "scanclean/drivers/sl_decode.h"

namespace scanclean {

struct SlCalibrateOptions {
  SlChessboard board;
  SlCornerOptions corners;
  int min_views = 3;              //!< captures with the board found in both, >= 3
  int min_projector_corners = 0;  //!< 0 = every corner must map into the projector
  //! Estimate k3 (the 6th-order radial term). Off by default: a few board poses cannot
  //! separate k2 from k3 and the fit trades them against each other (k2 = -27, k3 = 762 from
  //! the four kamino410 captures); k3 is then 0.
  bool estimate_k3 = false;
  bool zero_tangential = false;  //!< fix p1 = p2 = 0
};
//! \throw OptionError.
void validate(const SlCalibrateOptions& options);

struct SlCalibrationView {
  std::string name;             //!< capture folder (or index)
  bool used = false;            //!< found in camera and projector
  std::string reason;           //!< why not used
  int corners = 0;              //!< corners with a projector coordinate
  double camera_rms_px = 0;     //!< per-view reprojection RMS (camera pixels)
  double projector_rms_px = 0;  //!< per-view reprojection RMS (projector pixels)
};

struct SlCalibrateResult {
  SlCalibration calibration;  //!< unit metres, graycode_step 1, layout "scanclean"
  std::vector<SlCalibrationView> views;
  double camera_rms_px = 0;     //!< cv::calibrateCamera RMS (camera)
  double projector_rms_px = 0;  //!< cv::calibrateCamera RMS (projector)
  double stereo_rms_px = 0;     //!< cv::stereoCalibrate RMS (both)
};

//! Calibrates from decoded captures (same camera size and projector layout each).
//! \throw InputError when fewer than min_views captures show the board in both devices
//! (naming the captures and why), OptionError for bad options.
SlCalibrateResult calibrate_sl(const std::vector<SlCapture>& captures,
                               const std::vector<SlDecoded>& decoded,
                               const SlCalibrateOptions& options = {});

}  // namespace scanclean

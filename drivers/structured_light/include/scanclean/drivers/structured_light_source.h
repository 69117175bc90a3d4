#pragma once
//! \file structured_light_source.h
//! Structured-light captures as a RangeSource: one frame per capture folder (decode +
//! camera-projector triangulation), SourceInfo kind "structured-light", noise model
//! "structured-light". See sl_capture.h for the folder layouts.

#include <filesystem>
#include <memory>
#include <string>

#include "scanclean/core/point_cloud.h"
#include "scanclean/core/range_source.h"
#include "scanclean/drivers/sl_capture.h"
#include "scanclean/drivers/sl_decode.h"
#include "scanclean/drivers/sl_triangulate.h"

namespace scanclean {

struct SlOptions {
  int white_threshold = -1;           //!< gray levels; < 0 = the capture's (capture.json, else 5)
  int black_threshold = -1;           //!< gray levels; < 0 = the capture's (capture.json, else 40)
  std::filesystem::path calibration;  //!< calibration file override; empty = found beside
  SlDecoder decoder = SlDecoder::kFast;
  int projector_width = 0;  //!< > 0 overrides / supplies the projector size
  int projector_height = 0;
  int threads = 0;           //!< decoder threads, 0 = all cores
  bool sub_stripe = true;    //!< sub-stripe decoding (SlDecodeOptions::sub_stripe)
  int sub_stripe_level = 0;  //!< SlDecodeOptions::sub_stripe_level
  //! > 0 overrides the calibration's graycode_step (see SlCalibration). 0: the calibration's;
  //! for kamino410 calibrations, which do not record it, estimated from the decoded pixels
  //! (estimate_graycode_step).
  int graycode_step = 0;
  SlTriangulationOptions triangulation;
};
//! \throw OptionError naming the option, the value and the valid range.
void validate(const SlOptions& options);

//! `capture` is a capture folder, or a folder of capture folders (one frame each, sorted by
//! name). open() checks every capture's layout and the calibration; next() decodes and
//! triangulates the next one (a bad capture then gives kError with last_error()).
//! \throw InputError (from open()) for a folder without captures or a bad calibration.
std::unique_ptr<RangeSource> make_structured_light_source(const std::filesystem::path& capture,
                                                          const SlOptions& options = {});

//! Everything about one capture, for the command and tests.
struct SlResult {
  SlCaptureInfo info;
  SlCapture capture;  //!< the loaded images (shared, cheap to copy)
  SlCalibration calibration;
  SlDecoded decoded;
  RangeFrame frame;
  SlTriangulationStats triangulation;
  bool graycode_step_estimated = false;    //!< calibration.graycode_step was estimated
  double step_median_reprojection_px = 0;  //!< the estimate's median error (if estimated)
  double load_seconds = 0;
};
//! Loads, decodes and triangulates one capture folder. \throw InputError, OptionError.
SlResult process_sl_capture(const std::filesystem::path& folder, const SlOptions& options = {});

//! The valid points of a frame as an organized cloud (grid = frame size), metres, with the
//! confidences; no normals.
PointCloud sl_frame_to_cloud(const RangeFrame& frame);

}  // namespace scanclean

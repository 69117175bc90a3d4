#pragma once
//! \file sl_triangulate.h
//! Camera-projector triangulation of decoded Gray-code pixels (docs/SENSORS.md §5).
//!
//! Method: the camera ray of each pixel r_c = undistort(u, v) (cv::undistortPoints, exact camera
//! distortion) is taken as exact, the decoded projector pixel (column, row) is undistorted with
//! the projector distortion (cv::undistortPoints, iterated to convergence) to normalised
//! (x_p, y_p). A point X_c = lambda r_c projects onto the projector column plane and row plane
//! when n_k . (lambda R r_c + T) = 0 with n_1 = (1, 0, -x_p), n_2 = (0, 1, -y_p). lambda is the
//! least-squares solution of both equations, lambda = -(a1 b1 + a2 b2) / (a1^2 + a2^2),
//! a_k = n_k . R r_c, b_k = n_k . T. Each plane is thereby weighted by how well it cuts the ray,
//! so the method works for any baseline direction (the kamino410 rig's baseline is mostly
//! vertical, where the column plane alone is ill-conditioned) and needs no choice of axis.
//! The projector reprojection error of the solution (pixels) measures the epipolar consistency
//! of column and row; pixels above max_reprojection_px are rejected (wrong decodes,
//! interreflections).

#include <cstddef>
#include <memory>
#include <optional>

#include "scanclean/core/range_frame.h"
#include "scanclean/drivers/sl_calibration.h"
#include "scanclean/drivers/sl_decode.h"

namespace scanclean {

struct SlTriangulationOptions {
  //! Projector pixels, > 0. Wrong Gray-code bits give errors of many pixels; a real rig's
  //! calibration leaves a few pixels (kamino410 sample: median 2.6 px), hence 10.
  double max_reprojection_px = 10.0;
  double min_depth_m = 0;         //!< reject z below this (metres, >= 0)
  double max_depth_m = 0;         //!< reject z above this (metres); 0 = no limit
  double depth_unit_m = 1e-4;     //!< unit of RangeFrame::depth (100 um: up to 6.55 m)
  double calibration_unit_m = 0;  //!< metres per calibration unit; 0 = the calibration's
};
//! \throw OptionError naming the option, the value and the valid range.
void validate(const SlTriangulationOptions& options);

struct SlTriangulationStats {
  std::size_t decoded = 0;  //!< valid decoded pixels in
  std::size_t points = 0;   //!< triangulated points out
  std::size_t rejected_reprojection = 0;
  std::size_t rejected_depth = 0;   //!< behind a centre, ill-conditioned or outside the range
  double mean_reprojection_px = 0;  //!< over the points kept
  double seconds = 0;
};

//! Triangulates decoded captures for one calibration. The per-pixel camera rays and the
//! undistorted projector coordinates are computed once at construction (both sizes must be
//! known). Thread-safe const use.
class SlTriangulator {
 public:
  //! \throw InputError when the calibration lacks the camera or projector size.
  explicit SlTriangulator(const SlCalibration& calibration);
  ~SlTriangulator();
  SlTriangulator(SlTriangulator&&) noexcept;
  SlTriangulator& operator=(SlTriangulator&&) noexcept;

  //! An organized frame of the camera size: points (camera frame, metres, NaN invalid),
  //! confidence (decode confidence, 0 invalid), depth (z in options.depth_unit_m, 0 invalid)
  //! and K (the camera intrinsics with distortion).
  //! \throw InputError when the decoded image size differs from the calibrated camera size.
  RangeFrame triangulate(const SlDecoded& decoded, const SlTriangulationOptions& options = {},
                         SlTriangulationStats* stats = nullptr) const;

  const SlCalibration& calibration() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

//! Triangulates one camera pixel with one projector pixel (both continuous, pixels of the
//! calibrated images: a decoded coordinate times graycode_step), by the least-squares method
//! above, with both distortions undone. Returns the camera-frame point in metres (calibration
//! unit_m), or nothing when it lies behind a centre or the planes are ill-conditioned.
//! \p reprojection_px receives the projector reprojection error.
std::optional<Eigen::Vector3d> triangulate_sl_point(const SlCalibration& calibration,
                                                    const Eigen::Vector2d& camera_px,
                                                    const Eigen::Vector2d& projector_px,
                                                    double* reprojection_px = nullptr);

//! Median projector reprojection error (pixels) of the least-squares triangulation over up to
//! `samples` valid decoded pixels (evenly strided, deterministic) when the decoded Gray-code
//! pixel k is taken as projector pixel step * k. Returns +inf without valid pixels.
double sl_median_reprojection_px(const SlDecoded& decoded, const SlCalibration& calibration,
                                 int step, int samples = 4000);

//! The Gray-code step (1..4) under which the decoded pixels agree best with the calibration
//! (smallest median reprojection error). For calibrations that do not record the step
//! (kamino410's calibration_result.xml). \p median_px receives the winner's median error.
int estimate_graycode_step(const SlDecoded& decoded, const SlCalibration& calibration,
                           double* median_px = nullptr);

}  // namespace scanclean

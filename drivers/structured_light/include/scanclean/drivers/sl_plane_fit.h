#pragma once
//! \file sl_plane_fit.h
//! Robust plane fit for flat-target checks of structured-light scans: RANSAC (seeded) on the
//! points, then iterative trimmed least squares on the inliers. Used by `scanclean sl decode
//! --fit-plane` and the real-capture test (the kamino410 board).

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace scanclean {

struct PlaneFitOptions {
  double inlier_threshold = 0.002;  //!< metres; RANSAC inlier band (half width), > 0
  int ransac_iterations = 500;      //!< > 0
  std::uint64_t seed = 1;           //!< RANSAC RNG seed (results are deterministic)
  int refine_iterations = 5;        //!< trimmed least-squares rounds on the inliers
};

struct PlaneFit {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  //!< unit
  double offset = 0;                                  //!< plane: normal . x + offset = 0
  std::vector<std::size_t> inliers;                   //!< indices within the final band
  double rms = 0;                                     //!< RMS distance of the inliers (metres)
  double distance(const Eigen::Vector3d& p) const { return normal.dot(p) + offset; }
};

//! \throw OptionError for bad options or fewer than 3 points.
PlaneFit fit_plane_robust(const std::vector<Eigen::Vector3d>& points,
                          const PlaneFitOptions& options = {});

//! Least-squares plane through all the given points (no rejection); rms over all of them.
PlaneFit fit_plane_least_squares(const std::vector<Eigen::Vector3d>& points);

}  // namespace scanclean

#pragma once
//! \file filter_run.h
//! The benchmark's view of scanclean::robust_filter (compiled against the filter module only
//! when it is part of the build; otherwise filter_available() is false and run_robust_filter
//! throws UnavailableError).

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "scanclean/core/point_cloud.h"

namespace scanclean::bench {

struct FilterSettings {
  bool merge = false;     //!< false: merge_eps = 0 (protocol mode, counts match the input)
  bool adaptive = false;  //!< ScaleMode::kAdaptive with k_adaptive
  int k_adaptive = 48;
  int kernel_stride = 0;      //!< FilterOptions::kernel_stride (0 = automatic)
  int threads = 0;            //!< FilterOptions::threads (0 = all cores)
  double refit_spread = -1;   //!< FilterOptions::refit_spread (< 0: the library's default)
  double crease_spread = -1;  //!< FilterOptions::crease_spread (< 0: the library's default)
  //! FilterOptions::orient_k (as `scanclean filter --orient-normals K`; 0 = off).
  int orient_k = 0;
  //! > 0, for comparison: a cloud without normals gets them from CGAL first (PCA over this many
  //! neighbours, mst_orient_normals over half as many), used with
  //! FilterOptions::normals_orient_only (what `--orient-normals` did before the filter oriented
  //! normals itself); their time is part of seconds_wall.
  int cgal_orient_k = 0;
  int scale_regions = 0;             //!< FilterOptions::scale_regions (0: one h for the cloud)
  int k_h = 0;                       //!< FilterOptions::k_h (0: the library's default)
  int passes = 0;                    //!< FilterOptions::passes (0: the library's default)
  double scale_gamma = -1;           //!< FilterOptions::scale_gamma (< 0: the library's default)
  bool normals_orient_only = false;  //!< FilterOptions::normals_orient_only
  std::string describe() const;
};

struct FilterRun {
  PointCloud cloud;                           //!< filtered points (with the filter's attributes)
  std::vector<std::uint8_t> kept;             //!< per input point: 1 = represented in the output
  std::vector<std::int64_t> input_to_output;  //!< per input point: its output point (-1: none)
  double seconds_wall = 0;                    //!< measured around the call
  // FilterStats, copied so that callers need not see the filter header.
  double h = 0, noise_sigma = 0, mean_iterations = 0, p95_iterations = 0;
  std::size_t kernels = 0, kernels_refitted = 0, kernels_split = 0;
  std::size_t unsupported = 0, off_surface = 0, low_density = 0, low_likelihood = 0, displaced = 0,
              small_components = 0, merged = 0, not_converged = 0;
  double s_scale = 0, s_kernels = 0, s_projection = 0, s_clustering = 0, s_outliers = 0,
         s_total = 0;
};

bool filter_available();
FilterRun run_robust_filter(const PointCloud& input, const FilterSettings& settings);
//! Convenience: positions only.
FilterRun run_robust_filter(const std::vector<Eigen::Vector3d>& input,
                            const FilterSettings& settings);

}  // namespace scanclean::bench

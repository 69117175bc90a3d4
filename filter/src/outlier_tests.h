#pragma once
//! Internal: the outlier tests that decide which points the filter keeps (the paper's section
//! 2, "outlier removal", and this project's additions; FilterOptions documents each):
//!  - before the projection, the density test on each point's own kernel support (tau);
//!  - after the clustering, on the representatives: the density test (tau), the likelihood-ratio
//!    test, the displacement test and the small-component test.
//! The off-surface test, which also runs before the projection, lives in off_surface.h.

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "clustering.h"
#include "point_set.h"
#include "projection.h"
#include "scanclean/filter/filter_options.h"

namespace scanclean::detail {

//! Per point: 1 if its own kernel's support (KernelParams::support; < 0 where it has no kernel)
//! is below tau x the median over the kernels, else 0. The chi weights concentrate that count
//! within about h / 2, where a surface holds a quarter of its h-ball but volumetric clutter only
//! an eighth. Uniform clutter collapses into dense clumps under the projection and then passes
//! the density test on the output. Points without a kernel are left to the output tests.
//! `strides` (optional, one per point): the local kernel strides (kernel_sites.h); a kernel's
//! support then counts as often in the median as the points it stands for, so that thinning the
//! kernels where points are dense leaves the median, and the limit, where a kernel at every point
//! would put them.
std::vector<std::uint8_t> sparse_support(const std::vector<float>& support, double tau,
                                         const std::vector<std::uint8_t>* strides = nullptr);

//! Why a representative was removed.
enum class Removal : std::uint8_t {
  kKept,
  kLowDensity,      //!< rho below tau x the median rho
  kLowLikelihood,   //!< L below likelihood_ratio x the lower quartile of L around it
  kDisplaced,       //!< its move along its normal is an outlier among the moves around it
  kSmallComponent,  //!< in a component (link radius h) of fewer input points than the minimum
};

struct RepresentativeTestInput {
  const Clusters* clusters = nullptr;
  const std::vector<Eigen::Vector3d>* x = nullptr;  //!< projected positions (point order)
  const Projected* projected = nullptr;
  const PointSet* points = nullptr;  //!< for the per-point h_i
  //! Input positions (metres, absolute) and, per point, its input index: where each point
  //! started, relative to `origin`.
  const std::vector<Eigen::Vector3d>* input_positions = nullptr;
  const std::vector<std::uint32_t>* input_index = nullptr;
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  double cell = 0;            //!< grid cell of the representatives' index (ScaleChoice::h_grid)
  std::size_t stride = 1;     //!< kernel stride: the sums run over every stride-th representative
  std::size_t points_in = 0;  //!< input points (for the automatic minimum component size)
};

//! Runs the tests after the projection; returns one Removal per representative (in the order of
//! in.clusters). Deterministic, parallel.
std::vector<Removal> test_representatives(const RepresentativeTestInput& in,
                                          const FilterOptions& o);

}  // namespace scanclean::detail

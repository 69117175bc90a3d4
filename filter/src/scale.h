#pragma once
//! Internal: the scale phase, which chooses the kernel size (the paper's section 2, "choice of
//! h"; FilterOptions::scale): a fixed h; the automatic h (the median K_h-th neighbour distance
//! h0, raised to noise_factor x the noise sigma, then scale selection, scale_selection.h); or a
//! per-point h_i (the k_adaptive-th neighbour distance).

#include <Eigen/Core>
#include <memory>
#include <vector>

#include "neighbor_index.h"
#include "point_set.h"
#include "scanclean/filter/filter_options.h"

namespace scanclean::detail {

struct ScaleChoice {
  double h = 0;                    //!< the kernel size (kAdaptive: the median h_i)
  double h_min = 0, h_max = 0;     //!< range of h_i (kAdaptive, scale_regions; else both h)
  double h0 = 0;                   //!< kAuto: the median K_h-th neighbour distance
  double noise_sigma = 0;          //!< kAuto: median sqrt(lambda_3) at h_noise
  double noise_sigma_h0 = 0;       //!< kAuto: the same at h0
  double h_noise = 0;              //!< kAuto: max(h0, noise_factor sigma), before scale selection
  std::size_t crease_samples = 0;  //!< kAuto: the scale test's samples its crease test raised
  //! The size the neighbour grids are made for: h, or with h_i the 99th percentile of h_i
  //! (between h and 1.7 h). A query of radius r takes the grid's fast path (the 27 cells
  //! around a point) only when r is at most the cell; sized for the median h_i, half of the
  //! points took the slow one.
  double h_grid = 0;
  //! The size the kernel centres' grid is made for: with h_i the 99.9th percentile of h_i
  //! (between h_grid and 1.7 h). The projection's gathers take the grid's fast path only when
  //! their radius is at most the cell: sized for the 99th percentile, the 1 % of points with
  //! the largest h_i (the noisiest, which gather most often) made 77,000 of the 4.6M gathers of
  //! the 2.1M sphere at k = 250 take the slow path; the cache's parts (cell_select.h) keep the
  //! larger cells cheap for the others.
  double h_grid_kernels = 0;
  //! An index over pf with a cell between h_grid and 1.7 h_grid, when one was built on the way
  //! (else null): the kernels phase reuses it.
  std::unique_ptr<NeighborIndex> index;
};

//! Chooses h for the points `in` (input order; positions, sensor normals and weights set) whose
//! float copies relative to the same origin are `pf`; `diag` is the bounding-box diagonal. Sets
//! in.h, and in.hi for kAdaptive. Deterministic, parallel.
ScaleChoice choose_scale(PointSet& in, const std::vector<Eigen::Vector3f>& pf, double diag,
                         bool use_sensor_normals, const FilterOptions& o);

//! The most points a neighbourhood of a given h may hold at the median point. The work of the
//! kernels and the projection grows with the number of neighbours, and with the whole cloud
//! within h (a mistyped --h) it grows with the square of the cloud's size: 300,000 points ran
//! for minutes without an end. The automatic scales put from K_h to a few thousand there.
constexpr std::size_t kMaxMedianNeighbours = 20000;
//! Throws OptionError, before the kernels, when the median point of `index` (cell at least h)
//! has more than kMaxMedianNeighbours other points within h. Cheap when it does not: the 27
//! cells around a point hold its neighbours, and their median count is checked first.
void check_fixed_scale(const NeighborIndex& index, double h);

}  // namespace scanclean::detail

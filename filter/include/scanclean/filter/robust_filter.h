#pragma once
//! \file robust_filter.h
//! The robust filter of Schall, Belyaev, Seidel (2005), "Robust Filtering of Noisy Scattered
//! Point Data", as specified in docs/ALGORITHM.md: anisotropic likelihood kernels from weighted
//! PCA, a mean-shift-like projection of every point onto a maximum of the likelihood, greedy
//! clustering of the converged points and density-threshold outlier removal.
//!
//! Implementation notes (choices where the spec leaves room):
//!  - Coincident points (bitwise equal positions) are one observation: the phases run on the
//!    first copy of each position, and the other copies follow its fate (merged into its output
//!    point, merge_count counting them, or removed with it). Copies therefore neither shrink the
//!    automatic h nor cost quadratic time; a cloud of one position is one unsupported point.
//!  - Points far outside the bulk (beyond the box of the 1st to 99th percentiles grown by four
//!    times its size on every side) are filtered as a group of their own with the same options,
//!    so that a stray point at 1e7 m leaves the local float frame and the grid of the rest as
//!    they are (filter/src/input_groups.h).
//!  - Automatic h: the K_h-th neighbour distances are exact (grid radius queries); a k-d tree
//!    over a subsample only sizes the grid. If they are all 0 (K_h + 1 coincident points), h
//!    falls back to 1e-3 x the bounding-box diagonal (1 mm for a single location).
//!  - Kernels store S^-1 = E diag(1/lambda~) E^T (6 floats), so e_j = x^T S^-1 x = |W_j x|^2.
//!    Eigen-decomposition: closed form in double, in units of h^2 (accuracy checked in tests).
//!  - Projection runs in float relative to a per-point local origin; per-lane partial sums of
//!    the 8-wide (AVX2, else 4-wide SSE2) loops are combined in double in a fixed order.
//!  - Points without a kernel and without a sensor normal take the reference normal n_ref from
//!    the kernel with the smallest e_j at the first iteration.
//!  - Clustering: points flagged not_converged are kept as their own representatives (they
//!    neither join nor accept others). A representative reports the likelihood, iterations,
//!    normal and source_index of its seed (its highest-L member) and the L-weighted mean of its
//!    members' positions.
//!  - Density test: rho counts input points (member counts); the component-size test also
//!    counts input points.
//!  - Automatic h: after the noise rule, the scale test (scale_gamma, filter/src/scale_selection.h)
//!    sets one h for the cloud from plane fits in balls of 0.5-1.41 h_noise at 2,500 points.
//!  - Kernels are fitted robustly: the weighted PCA is repeated without the neighbours beyond
//!    3 standard deviations of its plane (at most twice).
//!  - Before the projection, points are dropped by the off-surface test (outlier_sigma) and by
//!    the density test on their own kernel's support (tau); see the options. After it, the
//!    converged points are dropped by the density, likelihood-ratio and displacement tests.
//!  - The normal update takes secant steps (at most 5x the measured step) once a previous
//!    iterate gives the slope; the stopping test uses the measured step, so the fixed points
//!    are unchanged.
//!
//! Known limits: two sheets closer than about 0.5 h collapse into one (at gaps of h or more
//! they stay apart); sharp creases are rounded; curvature bias grows with h^2 / R; near open
//! boundaries the error is about 1.6x higher; misregistered scan layers closer than h merge.
//!
//! The implementation follows the paper's outline, one file pair per phase (filter/src/):
//! scale (h), kernels (weighted PCA), projection (mean shift, with the off-surface test before
//! it), clustering, outlier_tests and outputs.

#include <cstddef>
#include <cstdint>

#include "scanclean/core/point_cloud.h"
#include "scanclean/filter/filter_options.h"

namespace scanclean {

//! Bits of the "flags" attribute.
enum FilterFlags : std::uint8_t {
  kFlagUnsupported = 1,  //!< no kernel supported the point (dropped)
  //! removed by the off-surface, density, likelihood-ratio or displacement test, or as a small
  //! component
  kFlagOutlier = 2,
  kFlagNotConverged = 4,  //!< iteration cap reached
};

struct FilterStats {
  std::size_t points_in = 0;
  std::size_t points_out = 0;
  std::size_t unsupported = 0;       //!< input points dropped: no support
  std::size_t low_density = 0;       //!< input points dropped by the density tests (tau)
  std::size_t off_surface = 0;       //!< input points dropped by the off-surface test
  std::size_t low_likelihood = 0;    //!< input points dropped by the likelihood-ratio test
  std::size_t displaced = 0;         //!< input points dropped by the displacement test
  std::size_t small_components = 0;  //!< input points dropped with small components
  //! Every input point dropped (unsupported, off surface, low density, low likelihood,
  //! displaced, small components).
  std::size_t removed() const {
    return unsupported + off_surface + low_density + low_likelihood + displaced + small_components;
  }
  std::size_t merged = 0;   //!< input points merged into another output point
  std::size_t kernels = 0;  //!< points that got a kernel (>= k_min neighbours)
  //! Kernels refitted on their own sheet (FilterOptions::refit_spread); with passes = 2, in
  //! both passes.
  std::size_t kernels_refitted = 0;
  //! Kernels fitted on their own face of a crease (FilterOptions::crease_spread); with
  //! passes = 2, in both passes.
  std::size_t kernels_split = 0;
  double h = 0;                 //!< kernel size (metres); kAdaptive: median h_i
  double h_min = 0, h_max = 0;  //!< range of h_i (equal to h unless kAdaptive or scale_regions)
  double h0 = 0;                //!< kAuto: the neighbour-distance median before the noise check
  double mean_spacing = 0;      //!< s = h0 / sqrt(K_h / pi) (kAuto), else h / sqrt(K / pi) (metres)
  double noise_sigma = 0;       //!< kAuto: median sqrt(lambda_3) at h_noise (metres)
  //! kAuto: the same where the fixed point starts: h0, or with K_h < 96 about the radius of 96
  //! neighbours (biased low when that is below ~6 sigma)
  double noise_sigma_h0 = 0;
  double h_noise = 0;  //!< kAuto: max(h0, noise_factor sigma), before the scale test (metres)
  //! kAuto with scale_regions and crease_spread: the scale test's samples (about 2,500) whose
  //! radius its crease test raised (a crease beside them, their own face flat farther out).
  std::size_t scale_crease_samples = 0;
  int kernel_stride = 1;  //!< kernels at every kernel_stride-th point
  double merge_eps = 0;   //!< merging distance used (metres)
  double mean_iterations = 0;
  double p95_iterations = 0;
  std::size_t not_converged = 0;
  double seconds_scale = 0, seconds_kernels = 0, seconds_projection = 0, seconds_clustering = 0,
         seconds_outliers = 0, seconds_total = 0;
  //! FilterOptions::orient_k: the trees of the neighbour graph the normals were oriented over,
  //! and the seconds it took (part of seconds_total, in none of the phases above).
  std::size_t orientation_trees = 0;
  double seconds_orientation = 0;
  std::size_t peak_rss_bytes = 0;  //!< process peak resident memory after the run (Linux)
  int threads = 0;                 //!< worker threads used
};

//! cloud: the filtered points (positions; normals = oriented surface normals; colours = the mean
//! of the merged input points'; intensities and confidences of the representative input point
//! when the input has them;
//! attributes "likelihood" float32, "iterations" uint8, "flags" uint8, "merge_count" uint32,
//! "source_index" uint32, "displacement" float32: metres from the representative's input point
//! along the output normal, signed, positive where the point moved along the normal). outliers:
//! every dropped input point at its input position, with the input's optional arrays and the
//! attributes "flags" (uint8) and "source_index" (uint32). Invariant: sum of merge_count over cloud
//! + outliers.size() == input.size().
struct FilterResult {
  PointCloud cloud;
  PointCloud outliers;
  FilterStats stats;
};

//! Filters `input` (metres). Input normals (non-zero) are sensor normals, input confidences
//! the weights w_i in [0, 1]. Deterministic: bit-identical output for any options.threads.
//! An empty input gives an empty result. \throw OptionError (validate), InputError when a
//! coordinate is not finite or a confidence is outside [0, 1] (names the point index).
//! Thread-safe (no shared state); runs its parallel work in its own TBB arena.
FilterResult robust_filter(const PointCloud& input, const FilterOptions& options = {});

}  // namespace scanclean

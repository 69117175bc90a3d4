#pragma once
//! Internal: the own-plane refit of a kernel (FilterOptions::refit_spread). Where one plane does
//! not explain a kernel's neighbourhood - two sheets of a thin part within h, a sharp crease, a
//! detail finer than h - its weighted PCA is a blend: a plane between the sheets, a rounded
//! crease, a plane cutting through a thin tube. Such a kernel is detected by its residual spread
//! (sqrt(lambda_3) above refit_spread x the cloud's noise sigma) and refitted on the neighbours
//! near the plane through its own centre point: only those within 3 noise sigma of the plane
//! (the plane refitted on them and the selection repeated, three times), provided the
//! neighbours left out hold at least 10 % of the chi weight (a second structure, not a noisy
//! plane whose spread is high by chance). The kernel then
//! describes its own sheet or its own side of the crease, and the projection's truncation
//! (Mahalanobis distance, slab) keeps the other side's kernels from pulling a point across.

#include <Eigen/Core>
#include <vector>

#include "kernel_fit.h"

namespace scanclean::detail {

struct PlaneRefit {
  double sigma = 0;           //!< the cloud's noise sigma (metres); 0 = no refit
  double ratio = 0;           //!< refit when sqrt(lambda_3) > ratio x sigma; 0 = no refit
  int k_min = 8;              //!< FilterOptions::k_min
  double eigen_floor = 0.05;  //!< FilterOptions::eigen_floor
  bool active() const { return sigma > 0 && ratio > 0; }
};

//! Whether `fit`'s residual spread asks for the refit (sqrt(lambda_3) > ratio x sigma).
inline bool wants_refit(const KernelFit& fit, const PlaneRefit& prm) {
  return prm.active() && fit.lambda[0] > prm.ratio * prm.ratio * prm.sigma * prm.sigma;
}

//! Refits `fit` (the robust weighted PCA of `samples`, offsets from `centre`, as fit_samples
//! made it) on the samples near the plane through the centre point, when its residual spread
//! asks for it (see above). Returns true if `fit` was replaced (its spread is then smaller).
//! Leaves `fit.n` as it was (the caller re-derives a PCA normal).
bool refit_own_plane(const std::vector<FitSample>& samples, const Eigen::Vector3d& centre, double h,
                     const PlaneRefit& prm, KernelFit& fit);

}  // namespace scanclean::detail

#pragma once
//! Internal: the refits of a kernel whose plane does not explain its neighbourhood - two sheets
//! of a thin part within h, a sharp crease, a detail finer than h - where its weighted PCA is a
//! blend: a plane between the sheets, a rounded crease, a plane cutting through a thin tube.
//! Such a kernel is detected by its residual spread (sqrt(lambda_3) above a ratio x the cloud's
//! noise sigma). The crease split (FilterOptions::crease_spread, split_crease below) fits it on
//! its own face of a crease. The sheet refit (FilterOptions::refit_spread, refit_own_plane)
//! fits it on the neighbours near the plane through its own centre point: only those within 3
//! noise sigma of the plane (the plane refitted on them and the selection repeated, three
//! times), provided the neighbours left out hold at least 10 % of the chi weight (a second
//! structure, not a noisy plane whose spread is high by chance; where the first band already
//! keeps over 95 % of it, the refit stops there). The kernel then describes its own sheet or its
//! own side of the crease, and the projection's truncation (Mahalanobis distance, slab) keeps
//! the other side's kernels from pulling a point across.

#include <Eigen/Core>
#include <vector>

#include "kernel_fit.h"

namespace scanclean::detail {

struct PlaneRefit {
  double sigma = 0;           //!< the cloud's noise sigma (metres); 0 = neither refit
  double ratio = 0;           //!< sheet refit when sqrt(lambda_3) > ratio x sigma; 0 = off
  double crease_ratio = 0;    //!< crease split when sqrt(lambda_3) > crease_ratio x sigma; 0 = off
  int k_min = 8;              //!< FilterOptions::k_min
  double eigen_floor = 0.05;  //!< FilterOptions::eigen_floor
  bool sheets() const { return sigma > 0 && ratio > 0; }
  bool creases() const { return sigma > 0 && crease_ratio > 0; }
};

//! Whether `fit`'s residual spread asks for the sheet refit (sqrt(lambda_3) > ratio x sigma).
inline bool wants_refit(const KernelFit& fit, const PlaneRefit& prm) {
  return prm.sheets() && fit.lambda[0] > prm.ratio * prm.ratio * prm.sigma * prm.sigma;
}
//! Whether `fit`'s residual spread asks for the crease split (sqrt(lambda_3) > crease_ratio x
//! sigma).
inline bool wants_split(const KernelFit& fit, const PlaneRefit& prm) {
  return prm.creases() &&
         fit.lambda[0] > prm.crease_ratio * prm.crease_ratio * prm.sigma * prm.sigma;
}

//! Refits `fit` (the robust weighted PCA of `samples`, offsets from `centre`, as fit_samples
//! made it) on the samples near the plane through the centre point, when its residual spread
//! asks for it (see above). Returns true if `fit` was replaced (its spread is then smaller).
//! Leaves `fit.n` as it was (the caller re-derives a PCA normal).
bool refit_own_plane(const std::vector<FitSample>& samples, const Eigen::Vector3d& centre, double h,
                     const PlaneRefit& prm, KernelFit& fit);

//! The crease split (FilterOptions::crease_spread), tried before refit_own_plane. Two faces
//! meeting at a sharp crease within h leave a kernel a blended plane (a rounded crease), and at
//! 2-3 % noise the band of refit_own_plane (3 sigma) holds both faces near the crease, so it
//! cannot separate them. Instead the neighbourhood is fitted with a wedge: two planes, each
//! sample given to its side by the plane through their line that separates the sides (started
//! from a split through the centroid in kCreaseDirections directions, kCreaseRounds rounds
//! each). The planes count every sample alike: with the chi weights, which peak at the centre
//! point, the apex blurred by the noise would flatten the wedge. It is only tried where the single
//! plane, fitted on the samples alike, leaves them more than kCreaseBend times the chi-weighted
//! spread lambda_3 (the far samples bend away from the plane). The wedge with the least mean
//! squared residual is kept if
//! - it leaves less than kCreaseGain of the single plane's residual,
//! - its planes' normals are more than 25 degrees apart (a noisy plane splits into two nearly
//!   parallel halves, two sheets into parallel planes: refit_own_plane's case),
//! - each side holds kCreaseMinShare of the chi weight, and
//! - its residual is below (kCreaseSpread sigma)^2: a surface bent within h (a small sphere, a
//!   torus' tube) is also fitted better by two planes than by one, but leaves more, and
//! - the centre point's face is flat: on its samples away from the line, a parabola across the
//!   line leaves less than kCreaseFlat sigma^2 (mean squared) below what its plane leaves. A
//!   rounded edge or a tube wider than h passes the residual test at 1 % noise (the torus and
//!   the rounded box at 10k points: CD up to 1.3 % worse with the split), but its faces are
//!   arcs.
//! The kernel is then fitted on the centre point's side of the wedge, without the samples within
//! kCreaseMargin sigma of the line (measured along the side's plane), where the two sides' noise
//! mixes. Its frame is that side's plane, refitted on those samples alike; its centroid, weight
//! and the variances within the frame are chi-weighted as the other kernels' are. Returns true
//! if `fit` was replaced; leaves `fit.n` as it was (the caller re-derives a normal from `fit.e`).
constexpr int kCreaseDirections = 4;
constexpr int kCreaseRounds = 5;
constexpr double kCreaseGain = 0.6;
constexpr double kCreaseCos = 0.9063;  // cos 25 degrees
constexpr double kCreaseMinShare = 0.15;
constexpr double kCreaseSpread = 1.3;
constexpr double kCreaseMargin = 2.0;
constexpr double kCreaseBend = 1.4;
constexpr double kCreaseFlat = 0.05;
//! The side of the crease split_crease kept: the points q (offsets from the centre point) with
//! (b . (q - p) > 0) == own lie on it.
struct CreaseSide {
  Eigen::Vector3d b = Eigen::Vector3d::UnitX(), p = Eigen::Vector3d::Zero();
  bool own = true;
  bool holds(const Eigen::Vector3d& q) const { return (b.dot(q - p) > 0) == own; }
};
bool split_crease(const std::vector<FitSample>& samples, const Eigen::Vector3d& centre,
                  const PlaneRefit& prm, KernelFit& fit, CreaseSide* side = nullptr);

//! split_crease's first test, on the samples' unweighted moments (fit_kernel's): whether the
//! single plane leaves the samples alike more than kCreaseBend times the chi-weighted spread
//! lambda_3 of `fit`. Where it does not, split_crease returns false; where it does, the samples
//! are worth gathering for it.
bool bends_away(const SampleMoments& moments, const KernelFit& fit);

}  // namespace scanclean::detail

#include "plane_refit.h"

#include <cmath>

namespace scanclean::detail {

bool refit_own_plane(const std::vector<FitSample>& samples, const Eigen::Vector3d& centre, double h,
                     const PlaneRefit& prm, KernelFit& fit) {
  if (!wants_refit(fit, prm)) return false;
  const double spread = std::sqrt(fit.lambda[0]);
  constexpr int kRounds = 3;
  constexpr double kMinOther = 0.1;
  const double band = 3.0 * prm.sigma;
  thread_local std::vector<FitSample> sel;
  Eigen::Vector3d n = fit.e.col(0);
  Eigen::Vector3d anchor = Eigen::Vector3d::Zero();  // the centre point
  KernelFit trial;
  for (int round = 0; round < kRounds; ++round) {
    sel.clear();
    for (const FitSample& q : samples) {
      const double r =
          n.x() * (q.x - anchor.x()) + n.y() * (q.y - anchor.y()) + n.z() * (q.z - anchor.z());
      if (std::abs(r) < band) sel.push_back(q);
    }
    if (!fit_samples(sel, centre, h, prm.k_min, prm.eigen_floor, trial)) return false;
    n = trial.e.col(0);
    anchor = trial.m;
  }
  // A second structure must hold a real share of the neighbourhood: on a noisy plane whose
  // spread is merely high by chance the band keeps almost everything (over 99 %).
  double total = 0;
  for (const FitSample& q : samples) total += q.t;
  if (!(trial.weight < (1.0 - kMinOther) * total)) return false;
  if (!(std::sqrt(trial.lambda[0]) < spread)) return false;
  const Eigen::Vector3f n_kept = fit.n;  // the caller's (a sensor normal stays)
  fit = trial;
  fit.n = n_kept;
  return true;
}

}  // namespace scanclean::detail

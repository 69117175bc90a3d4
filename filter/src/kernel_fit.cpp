#include "kernel_fit.h"

#include <Eigen/Eigenvalues>
#include <algorithm>

namespace scanclean::detail {

bool fit_samples(std::vector<FitSample>& nb, const Eigen::Vector3d& centre, double h, int k_min,
                 double eigen_floor, KernelFit& out) {
  constexpr double kTrim = 3.0;
  constexpr int kRefits = 2;
  const double h2 = h * h, inv_h2 = 1.0 / h2;
  const double floor2 = eigen_floor * eigen_floor;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
  Eigen::Vector3d m;
  Eigen::Matrix3d cov;
  double s0_final = 0;
  for (int round = 0;; ++round) {
    double s0 = 0, sx = 0, sy = 0, sz = 0, sxx = 0, syy = 0, szz = 0, sxy = 0, sxz = 0, syz = 0;
    for (const FitSample& q : nb) {
      const double t = q.t;
      s0 += t;
      sx += t * q.x;
      sy += t * q.y;
      sz += t * q.z;
      sxx += t * q.x * q.x;
      syy += t * q.y * q.y;
      szz += t * q.z * q.z;
      sxy += t * q.x * q.y;
      sxz += t * q.x * q.z;
      syz += t * q.y * q.z;
    }
    if (static_cast<int>(nb.size()) < k_min || !(s0 > 0)) return false;
    s0_final = s0;
    m = Eigen::Vector3d(sx / s0, sy / s0, sz / s0);
    Eigen::Matrix3d c;
    c(0, 0) = sxx / s0 - m.x() * m.x();
    c(1, 1) = syy / s0 - m.y() * m.y();
    c(2, 2) = szz / s0 - m.z() * m.z();
    c(0, 1) = c(1, 0) = sxy / s0 - m.x() * m.y();
    c(0, 2) = c(2, 0) = sxz / s0 - m.x() * m.z();
    c(1, 2) = c(2, 1) = syz / s0 - m.y() * m.z();
    // Solve in units of h^2 (well scaled); closed form, checked against the QR solver in tests.
    cov = c * inv_h2;
    es.computeDirect(cov);
    if (round == kRefits) break;
    // Trim (in units of h): residuals from the plane beyond kTrim standard deviations.
    const Eigen::Vector3d n = es.eigenvectors().col(0);
    const double var = std::max(es.eigenvalues()[0], floor2);
    const double limit2 = kTrim * kTrim * var * h2;
    const std::size_t before = nb.size();
    nb.erase(std::remove_if(nb.begin(), nb.end(),
                            [&](const FitSample& q) {
                              const double r = n.x() * (q.x - m.x()) + n.y() * (q.y - m.y()) +
                                               n.z() * (q.z - m.z());
                              return r * r > limit2;
                            }),
             nb.end());
    if (nb.size() == before) break;
  }
  out.weight = s0_final;
  out.m = m;
  out.cov = cov * h2;
  out.c = centre + m;
  out.lambda = es.eigenvalues().cwiseMax(0.0) * h2;
  out.e = es.eigenvectors();
  return true;
}

}  // namespace scanclean::detail

#include "off_surface.h"

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <utility>

#include "kernel_fit.h"

namespace scanclean::detail {

bool downdate_fit(Eigen::Vector3d& m, Eigen::Matrix3d& cov, double& w, const Eigen::Vector3d& p,
                  double t, double min_weight) {
  const double w1 = w - t;
  if (!(w1 > min_weight)) return false;
  const Eigen::Vector3d delta = p - m;
  m -= (t / w1) * delta;
  cov = (w / w1) * cov - (t * w / (w1 * w1)) * delta * delta.transpose();
  w = w1;
  return true;
}

void floored_mahalanobis(const Eigen::Matrix3d& c, const Eigen::Vector3d& y, double floor2,
                         double& e, double& y0) {
  Eigen::Vector3d n0;
  double l0 = 0;
  if (smallest_eigenpair(c, l0, n0) && l0 >= floor2) {
    // No eigenvalue is below the floor: S is c itself.
    e = y.dot(c.inverse() * y);
    y0 = n0.dot(y);
    return;
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
  es.computeDirect(c);
  const Eigen::Vector3d yl = es.eigenvectors().transpose() * y;
  e = 0;
  for (int k = 0; k < 3; ++k) e += yl[k] * yl[k] / std::max(es.eigenvalues()[k], floor2);
  y0 = yl[0];
}

bool vouched(const OffSurfaceTest& test, CandidateBuffer& buf, const Eigen::Vector3d& xl,
             const Eigen::Vector3f& nref) {
  using B = CandidateBuffer;
  const float* e = buf.f[B::kE].data();
  // Whether the point's sensor normal lets it into kernel j's fit.
  auto normals_agree_with = [&](std::size_t j) {
    const Eigen::Vector3f nj(buf.f[B::kNx][j], buf.f[B::kNy][j], buf.f[B::kNz][j]);
    return !(test.oriented && nref.squaredNorm() > 0.5f) || nref.dot(nj) > 0.5f;
  };
  // Any kernel that vouches will do, so the ones that vouch on upper bounds of the two weights
  // alone are looked for first, over all candidates: the band test (below) can only lower the
  // weights, and with under 10 % of the fit's weight the downdate cannot move the point past
  // the threshold from within half of it. No eigen-decomposition is needed for these.
  const float quick2 = 0.25f * test.threshold2;
  for (std::size_t j = 0; j < buf.count; ++j) {
    if (!(e[j] <= quick2)) continue;
    const KernelFitRecord& fit = test.kernels->fits[buf.slot[j]];
    const Eigen::Vector3d c(buf.f[B::kCx][j], buf.f[B::kCy][j], buf.f[B::kCz][j]);
    const Eigen::Vector3d d0 = xl - (c - fit.offset());
    const double r2 = d0.squaredNorm();
    const double t_bound =
        (normals_agree_with(j) && r2 < buf.f[B::kH2][j] ? 1.0 : 0.0) + (r2 == 0.0 ? 0.0 : 1.0);
    if (t_bound <= 0.1 * fit.weight) return true;
  }
  for (std::size_t j = 0; j < buf.count; ++j) {
    if (!(e[j] <= test.threshold2)) continue;
    const KernelFitRecord& fit = test.kernels->fits[buf.slot[j]];
    Eigen::Vector3d m = fit.offset();
    const Eigen::Vector3d c(buf.f[B::kCx][j], buf.f[B::kCy][j], buf.f[B::kCz][j]);
    const Eigen::Vector3d d0 = xl - (c - m);  // from the kernel's centre point
    const double h2 = buf.f[B::kH2][j];
    Eigen::Matrix3d cov = fit.covariance();
    double w = fit.weight;
    // In the fit: within h of the centre, the sensor normals agreeing, inside the trimming band.
    const bool normals_agree = normals_agree_with(j);
    const bool is_centre = d0.squaredNorm() == 0.0;
    // The fit's plane (its smallest eigenpair) decides whether the two points are in it.
    Eigen::Vector3d n0;
    double l0 = 0;
    if (!smallest_eigenpair(cov / h2, l0, n0)) {
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
      es.computeDirect(cov / h2);
      n0 = es.eigenvectors().col(0);
      l0 = es.eigenvalues()[0];
    }
    const double band2 = 9.0 * std::max(l0, test.floor2) * h2;
    auto weight_in_fit = [&](const Eigen::Vector3d& p) {
      const double pr2 = p.squaredNorm();
      if (!(pr2 < h2)) return 0.0;
      const double res = n0.dot(p - m);
      if (res * res > band2) return 0.0;
      double t = 1.0 - pr2 / h2;
      t *= t;
      return t * t;
    };
    const double t_point = normals_agree ? weight_in_fit(d0) : 0.0;
    const double t_centre = is_centre ? 0.0 : weight_in_fit(Eigen::Vector3d::Zero());
    if (t_point + t_centre <= 0.1 * w && e[j] <= 0.25f * test.threshold2) return true;
    bool ok = true;
    const double min_weight = 1e-3 * fit.weight;
    for (const auto& [p, t] :
         {std::pair{d0, t_point}, std::pair{Eigen::Vector3d(0, 0, 0), t_centre}}) {
      if (!(t > 0)) continue;
      if (!downdate_fit(m, cov, w, p, t, min_weight)) {
        ok = false;
        break;
      }
    }
    if (!ok) continue;
    const Eigen::Vector3d y = (d0 - m) / std::sqrt(h2);  // in units of h
    double e1 = 0, y0 = 0;
    floored_mahalanobis(cov / h2, y, test.floor2, e1, y0);
    if (e1 <= test.threshold2 && y0 * y0 * h2 < buf.f[B::kSlab2][j]) return true;
  }
  return false;
}

}  // namespace scanclean::detail

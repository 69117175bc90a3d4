// The off-surface test's leave-one-out downdate (filter/src/off_surface.h) against a full refit
// without the points taken out (the oracle).

#include "../../filter/src/off_surface.h"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <random>

#include "../../filter/src/kernel_fit.h"
#include "support/synthetic.h"

namespace scanclean::detail {
namespace {

struct Moments {
  Eigen::Vector3d m = Eigen::Vector3d::Zero();
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  double w = 0;
};

Moments refit(const std::vector<Eigen::Vector3d>& p, const std::vector<double>& t,
              const std::vector<bool>& skip) {
  Moments r;
  for (std::size_t k = 0; k < p.size(); ++k)
    if (!skip[k]) {
      r.w += t[k];
      r.m += t[k] * p[k];
    }
  r.m /= r.w;
  for (std::size_t k = 0; k < p.size(); ++k)
    if (!skip[k]) r.cov += t[k] * (p[k] - r.m) * (p[k] - r.m).transpose();
  r.cov /= r.w;
  return r;
}

TEST(OffSurfaceTest, DowndateEqualsAFullRefitWithoutThePoints) {
  std::mt19937 rng(21);
  std::normal_distribution<double> g(0.0, 1.0);
  std::uniform_real_distribution<double> u(0.05, 1.0);
  for (int trial = 0; trial < 50; ++trial) {
    const int n = 20 + trial;
    std::vector<Eigen::Vector3d> p(n);
    std::vector<double> t(n);
    for (int k = 0; k < n; ++k) {
      const double z = 0.1 * g(rng), y = g(rng), x = g(rng);  // gcc's order (test::draw_point)
      p[k] = Eigen::Vector3d(x, y, z) * 1e-3;
      t[k] = u(rng);
    }
    std::vector<bool> skip(n, false);
    Moments fit = refit(p, t, skip);
    // Take out two samples, one after the other, as the test does (the point, then the centre).
    for (int k : {trial % n, (trial * 7 + 3) % n}) {
      if (skip[k]) continue;
      ASSERT_TRUE(downdate_fit(fit.m, fit.cov, fit.w, p[k], t[k], 1e-3 * fit.w));
      skip[k] = true;
      const Moments ref = refit(p, t, skip);
      EXPECT_NEAR(fit.w, ref.w, 1e-12 * ref.w);
      EXPECT_LT((fit.m - ref.m).norm(), 1e-12 * 1e-3);
      EXPECT_LT((fit.cov - ref.cov).norm(), 1e-10 * ref.cov.norm()) << "trial " << trial;
    }
  }
}

TEST(OffSurfaceTest, FlooredMahalanobisEqualsTheEigenDecomposition) {
  // The oracle: y in the eigenbasis of Eigen's iterative solver, each component over its
  // eigenvalue floored. Covariances with no eigenvalue under the floor (the inverse path) and
  // with the normal one under it (the decomposition path).
  std::mt19937 rng(22);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double floor2 = 0.05 * 0.05;
  int floored = 0;
  for (int trial = 0; trial < 400; ++trial) {
    // Draws in one argument list, written out last to first: gcc's order (test::draw_point).
    const double qz = u(rng), qy = u(rng), qx = u(rng), qw = u(rng);
    const Eigen::Matrix3d rot = Eigen::Quaterniond(qw, qx, qy, qz).normalized().toRotationMatrix();
    const double l0 = trial % 2 == 0 ? 0.01 * (1.5 + u(rng)) : 1e-3 * (1.5 + u(rng));
    const double l2 = 0.12 + 0.02 * u(rng), l1 = 0.08 + 0.02 * u(rng);
    const Eigen::Vector3d ev(l0, l1, l2);
    const Eigen::Matrix3d c = rot * ev.asDiagonal() * rot.transpose();
    const Eigen::Vector3d y = test::draw_point(rng, u, u, u);
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> ref(c);
    const Eigen::Vector3d yl = ref.eigenvectors().transpose() * y;
    double want = 0;
    for (int k = 0; k < 3; ++k) want += yl[k] * yl[k] / std::max(ref.eigenvalues()[k], floor2);
    floored += ref.eigenvalues()[0] < floor2 ? 1 : 0;
    double e = 0, y0 = 0;
    floored_mahalanobis(c, y, floor2, e, y0);
    EXPECT_NEAR(e, want, 1e-12 * want) << "trial " << trial;
    EXPECT_NEAR(std::abs(y0), std::abs(yl[0]), 1e-12) << "trial " << trial;
  }
  EXPECT_GT(floored, 100);
  EXPECT_LT(floored, 300);
}

TEST(OffSurfaceTest, DowndateRefusesToEmptyTheFit) {
  Eigen::Vector3d m(1, 2, 3);
  Eigen::Matrix3d cov = Eigen::Matrix3d::Identity();
  double w = 1.0;
  EXPECT_FALSE(downdate_fit(m, cov, w, Eigen::Vector3d(1, 2, 3), 1.0, 1e-3));
  EXPECT_EQ(w, 1.0);
  EXPECT_EQ(m, Eigen::Vector3d(1, 2, 3));
}

}  // namespace
}  // namespace scanclean::detail

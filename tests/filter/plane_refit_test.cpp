// The own-plane refit of a kernel (filter/src/plane_refit.h): two sheets within h and a sharp
// crease, where the weighted PCA blends, against a plain plane, where it must not act.

#include "../../filter/src/plane_refit.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "../../filter/src/kernel_fit.h"

namespace scanclean::detail {
namespace {

constexpr double kH = 1.0;
constexpr double kSigma = 0.02;

// Samples (offsets from the centre point at the origin) with their chi weights, from points
// drawn uniformly in the ball's square [-h, h]^2 and mapped onto the surface by `place`, plus
// Gaussian noise along z (seeded).
template <class Place>
std::vector<FitSample> samples(std::size_t n, std::uint32_t seed, Place&& place) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-kH, kH);
  std::normal_distribution<double> g(0.0, kSigma);
  std::vector<FitSample> out;
  while (out.size() < n) {
    const Eigen::Vector3d p = place(u(rng), u(rng), g(rng));
    const double r2 = p.squaredNorm();
    if (!(r2 < kH * kH)) continue;
    double t = 1.0 - r2 / (kH * kH);
    t *= t;
    out.push_back({p.x(), p.y(), p.z(), t * t});
  }
  return out;
}

PlaneRefit refit_options() {
  PlaneRefit r;
  r.sigma = kSigma;
  r.ratio = 1.5;
  return r;
}

TEST(PlaneRefitTest, TwoSheetsWithinHKeepTheCentrePointsSheet) {
  // Sheets z = 0 (the centre point's) and z = 0.3 h, 400 samples each.
  auto fit_of = [](std::vector<FitSample> nb, KernelFit& fit) {
    return fit_samples(nb, Eigen::Vector3d::Zero(), kH, 8, 0.05, fit);
  };
  std::vector<FitSample> nb =
      samples(400, 1, [](double x, double y, double z) { return Eigen::Vector3d(x, y, z); });
  const std::vector<FitSample> other =
      samples(400, 2, [](double x, double y, double z) { return Eigen::Vector3d(x, y, 0.3 + z); });
  nb.insert(nb.end(), other.begin(), other.end());
  KernelFit fit;
  ASSERT_TRUE(fit_of(nb, fit));
  // The plain fit: a plane between the sheets, spread about half the gap.
  EXPECT_GT(fit.m.z(), 0.1);
  EXPECT_GT(std::sqrt(fit.lambda[0]), 0.1);
  fit.n = Eigen::Vector3f(0, 0, -1);  // e.g. a sensor normal: the refit leaves it
  ASSERT_TRUE(refit_own_plane(nb, Eigen::Vector3d::Zero(), kH, refit_options(), fit));
  EXPECT_EQ(fit.n, Eigen::Vector3f(0, 0, -1));
  EXPECT_NEAR(fit.m.z(), 0.0, 0.01);
  EXPECT_LT(std::sqrt(fit.lambda[0]), 1.2 * kSigma);
  EXPECT_GT(std::abs(fit.e.col(0).z()), 0.999);
  EXPECT_NEAR(fit.c.z(), 0.0, 0.01);  // centre = centre point + m
}

TEST(PlaneRefitTest, ACreaseKernelTakesItsOwnFace) {
  // A convex 90-degree edge at x = 0.3 h: face A (z = 0, x < 0.3, the centre point's) and face B
  // (x = 0.3, z < 0). Points of the square beyond x = 0.3 fold down onto face B.
  const double e = 0.3;
  const std::vector<FitSample> nb = samples(800, 3, [e](double x, double y, double z) {
    return x < e ? Eigen::Vector3d(x, y, z) : Eigen::Vector3d(e + z, y, -(x - e));
  });
  std::vector<FitSample> copy = nb;
  KernelFit fit;
  ASSERT_TRUE(fit_samples(copy, Eigen::Vector3d::Zero(), kH, 8, 0.05, fit));
  const double tilt_before = std::acos(std::min(1.0, std::abs(fit.e.col(0).z())));
  EXPECT_GT(tilt_before, 0.1);  // the plain fit rounds the crease: its normal is tilted
  ASSERT_TRUE(refit_own_plane(nb, Eigen::Vector3d::Zero(), kH, refit_options(), fit));
  const double tilt_after = std::acos(std::min(1.0, std::abs(fit.e.col(0).z())));
  EXPECT_LT(tilt_after, 0.25 * tilt_before) << tilt_before;
  EXPECT_LT(tilt_after, 0.05);
  EXPECT_NEAR(fit.m.z(), 0.0, 0.01);
}

TEST(PlaneRefitTest, APlaneAndAnInactiveRefitLeaveTheFitAlone) {
  std::vector<FitSample> nb =
      samples(600, 4, [](double x, double y, double z) { return Eigen::Vector3d(x, y, z); });
  std::vector<FitSample> copy = nb;
  KernelFit fit;
  ASSERT_TRUE(fit_samples(copy, Eigen::Vector3d::Zero(), kH, 8, 0.05, fit));
  const KernelFit before = fit;
  EXPECT_FALSE(refit_own_plane(nb, Eigen::Vector3d::Zero(), kH, refit_options(), fit));
  EXPECT_EQ(fit.m, before.m);
  EXPECT_EQ(fit.lambda, before.lambda);
  // Two sheets, but the refit is off (no noise estimate, or ratio 0).
  const std::vector<FitSample> other =
      samples(600, 5, [](double x, double y, double z) { return Eigen::Vector3d(x, y, 0.3 + z); });
  nb.insert(nb.end(), other.begin(), other.end());
  copy = nb;
  ASSERT_TRUE(fit_samples(copy, Eigen::Vector3d::Zero(), kH, 8, 0.05, fit));
  PlaneRefit off = refit_options();
  off.sigma = 0;
  EXPECT_FALSE(refit_own_plane(nb, Eigen::Vector3d::Zero(), kH, off, fit));
  off = refit_options();
  off.ratio = 0;
  EXPECT_FALSE(refit_own_plane(nb, Eigen::Vector3d::Zero(), kH, off, fit));
}

}  // namespace
}  // namespace scanclean::detail

// The own-plane refit of a kernel and the crease split (filter/src/plane_refit.h): two sheets
// within h and a sharp crease, where the weighted PCA blends, against a plain plane, where they
// must not act.

#include "../../filter/src/plane_refit.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <utility>
#include <vector>

#include "../../filter/src/kernel_fit.h"
#include "support/synthetic.h"

namespace scanclean::detail {
namespace {

constexpr double kH = 1.0;
constexpr double kSigma = 0.02;

// Appends p (an offset from the centre point at the origin) with its chi weight
// t = (1 - r^2 / h^2)^4 when it lies within h.
void add_within_h(const Eigen::Vector3d& p, std::vector<FitSample>& out) {
  const double r2 = p.squaredNorm();
  if (!(r2 < kH * kH)) return;
  double t = 1.0 - r2 / (kH * kH);
  t *= t;
  out.push_back({p.x(), p.y(), p.z(), t * t});
}

// Samples (offsets from the centre point at the origin) with their chi weights, from points
// drawn uniformly in the ball's square [-h, h]^2 and mapped onto the surface by `place`, plus
// Gaussian noise along z (seeded).
template <class Place>
std::vector<FitSample> samples(std::size_t n, std::uint32_t seed, Place&& place,
                               double sigma = kSigma) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-kH, kH);
  std::normal_distribution<double> g(0.0, sigma);
  std::vector<FitSample> out;
  while (out.size() < n) {
    const Eigen::Vector3d r = test::draw_point(rng, u, u, g);
    const Eigen::Vector3d p = place(r.x(), r.y(), r.z());
    add_within_h(p, out);
  }
  return out;
}

PlaneRefit refit_options() {
  PlaneRefit r;
  r.sigma = kSigma;
  r.ratio = 1.5;
  r.crease_ratio = 1.5;
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

// A convex 90-degree crease at x = e, as above, under noise of 0.15 h (the benchmark's sharp
// box at 50k points and 3 % noise has sigma / h = 0.2): face A (z = 0, x < e) and face B
// (x = e, z < 0), or the mirror image (face A for x > e).
std::vector<FitSample> noisy_crease(double e, bool mirrored, std::uint32_t seed) {
  constexpr double kNoisy = 0.15;
  return samples(
      1500, seed,
      [e, mirrored](double x, double y, double z) {
        const bool on_a = mirrored ? x > e : x < e;
        return on_a ? Eigen::Vector3d(x, y, z) : Eigen::Vector3d(e + z, y, -std::abs(x - e));
      },
      kNoisy);
}

// The cloud's noise estimate below the true 0.15 h, as the filter's is there (24.5 mm against
// 30 mm on that box).
PlaneRefit noisy_refit_options() {
  PlaneRefit r;
  r.sigma = 0.13;
  r.ratio = 1.1;
  r.crease_ratio = 1.1;
  return r;
}

double tilt_from_z(const KernelFit& fit) {
  return std::acos(std::min(1.0, std::abs(fit.e.col(0).z())));
}

TEST(PlaneRefitTest, UnderHeavyNoiseTheCreaseSplitGivesTheKernelItsOwnFace) {
  for (const bool mirrored : {false, true}) {
    for (const double e : {0.1, 0.25}) {
      SCOPED_TRACE(::testing::Message() << "crease at x = " << (mirrored ? -e : e));
      const std::vector<FitSample> nb = noisy_crease(mirrored ? -e : e, mirrored, 11);
      std::vector<FitSample> copy = nb;
      KernelFit plain;
      ASSERT_TRUE(fit_samples(copy, Eigen::Vector3d::Zero(), kH, 8, 0.05, plain));
      EXPECT_GT(tilt_from_z(plain), 0.2);                 // blended: tilted by more than 11 degrees
      EXPECT_GT(std::sqrt(plain.lambda[0]), 1.1 * 0.13);  // so the spread asks for a refit
      // The band of the own-plane refit (3 sigma = 0.45 h) holds both faces near the crease:
      // it leaves a tilted plane or none.
      KernelFit own = plain;
      if (refit_own_plane(nb, Eigen::Vector3d::Zero(), kH, noisy_refit_options(), own)) {
        EXPECT_GT(tilt_from_z(own), 0.1);
      }
      KernelFit split = plain;
      split.n = Eigen::Vector3f(0, 0, 1);  // e.g. a sensor normal: the split leaves it
      ASSERT_TRUE(split_crease(nb, Eigen::Vector3d::Zero(), noisy_refit_options(), split));
      EXPECT_EQ(split.n, Eigen::Vector3f(0, 0, 1));
      EXPECT_LT(tilt_from_z(split), 0.07) << "plain " << tilt_from_z(plain);  // 4 degrees
      EXPECT_NEAR(split.m.z(), 0.0, 0.03);  // on face A, the centre point's
      EXPECT_LT(std::sqrt(split.lambda[0]), 1.15 * 0.15);
      // Face A only: its centroid lies on the centre point's side of the crease.
      EXPECT_TRUE(mirrored ? split.m.x() > -e : split.m.x() < e) << split.m.x();
    }
  }
}

TEST(PlaneRefitTest, TheCreaseSplitLeavesANoisyPlaneAndParallelSheetsAlone) {
  const PlaneRefit prm = noisy_refit_options();
  for (std::uint32_t seed = 20; seed < 25; ++seed) {
    // A plane with the same noise; its spread is pushed over the trigger so the split is tried.
    const std::vector<FitSample> plane = samples(
        1500, seed, [](double x, double y, double z) { return Eigen::Vector3d(x, y, z); }, 0.15);
    std::vector<FitSample> copy = plane;
    KernelFit fit;
    ASSERT_TRUE(fit_samples(copy, Eigen::Vector3d::Zero(), kH, 8, 0.05, fit));
    fit.lambda[0] = 4 * 0.13 * 0.13;
    const Eigen::Vector3d m_before = fit.m;
    EXPECT_FALSE(split_crease(plane, Eigen::Vector3d::Zero(), prm, fit)) << seed;
    EXPECT_EQ(fit.m, m_before);
  }
  // Two parallel sheets 0.3 h apart (the own-plane refit's case): no crease between them.
  std::vector<FitSample> nb =
      samples(600, 30, [](double x, double y, double z) { return Eigen::Vector3d(x, y, z); });
  const std::vector<FitSample> other =
      samples(600, 31, [](double x, double y, double z) { return Eigen::Vector3d(x, y, 0.3 + z); });
  nb.insert(nb.end(), other.begin(), other.end());
  std::vector<FitSample> copy = nb;
  KernelFit fit;
  ASSERT_TRUE(fit_samples(copy, Eigen::Vector3d::Zero(), kH, 8, 0.05, fit));
  EXPECT_FALSE(split_crease(nb, Eigen::Vector3d::Zero(), refit_options(), fit));
  EXPECT_TRUE(refit_own_plane(nb, Eigen::Vector3d::Zero(), kH, refit_options(), fit));
}

TEST(PlaneRefitTest, TheCreaseSplitLeavesASurfaceBentWithinHAlone) {
  // A tube of radius 0.6 h along y, the centre point on its top, noise 0.05 h along the radius:
  // a wedge fits it better than one plane, but not down to the noise.
  constexpr double kR = 0.6, kNoise = 0.05;
  std::mt19937 rng(40);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::normal_distribution<double> g(0.0, kNoise);
  std::vector<FitSample> nb;
  while (nb.size() < 1500) {
    const double dz = u(rng), dx = u(rng);  // in the xz section; order as test::draw_point
    const Eigen::Vector2d dir(dx, dz);
    const double y = u(rng);
    if (!(dir.squaredNorm() > 1e-6 && dir.squaredNorm() < 1)) continue;
    const Eigen::Vector2d xz = (kR + g(rng)) * dir.normalized();
    const Eigen::Vector3d p(xz.x(), y, xz.y() - kR);
    add_within_h(p, nb);
  }
  std::vector<FitSample> copy = nb;
  KernelFit fit;
  ASSERT_TRUE(fit_samples(copy, Eigen::Vector3d::Zero(), kH, 8, 0.05, fit));
  PlaneRefit prm;
  prm.sigma = kNoise;
  prm.crease_ratio = 1.1;
  ASSERT_TRUE(wants_split(fit, prm));  // the bend makes the plane's spread large
  KernelFit kept = fit;
  EXPECT_FALSE(split_crease(nb, Eigen::Vector3d::Zero(), prm, kept));
  EXPECT_EQ(kept.m, fit.m);
  // With a noise estimate four times as large the same wedge passes: it is the spread test
  // that rejects it.
  prm.sigma = 4 * kNoise;
  prm.crease_ratio = 0.1;
  EXPECT_TRUE(split_crease(nb, Eigen::Vector3d::Zero(), prm, fit));
}

// Samples around a centre point on face A (z = 0, x < 0) of a 90-degree edge along y whose
// face B is x = 0, z < 0; the edge rounded with radius rho (0: sharp). The centre point at
// x = -c. Noise along the profile's normal (seeded).
std::vector<FitSample> edge_samples(double rho, double c, double sigma, std::uint32_t seed) {
  std::mt19937 rng(seed);
  const double len_a = 2.0, len_arc = 0.5 * M_PI * rho, len_b = 2.0;
  std::uniform_real_distribution<double> u(0.0, len_a + len_arc + len_b), uy(-kH, kH);
  std::normal_distribution<double> g(0.0, sigma);
  std::vector<FitSample> out;
  while (out.size() < 1500) {
    const double s = u(rng), y = uy(rng), e = g(rng);
    Eigen::Vector2d p, n;  // in the xz profile
    if (s < len_a) {
      p = Eigen::Vector2d(-rho - (len_a - s), 0);
      n = Eigen::Vector2d(0, 1);
    } else if (s < len_a + len_arc) {
      const double a = (s - len_a) / std::max(rho, 1e-12);  // from +z towards +x
      n = Eigen::Vector2d(std::sin(a), std::cos(a));
      p = Eigen::Vector2d(-rho, -rho) + rho * n;
    } else {
      p = Eigen::Vector2d(0, -rho - (s - len_a - len_arc));
      n = Eigen::Vector2d(1, 0);
    }
    p += e * n;
    const Eigen::Vector3d q(p.x() + c, y, p.y());
    add_within_h(q, out);
  }
  return out;
}

// The split at an edge rounded with radius rho, noise sigma (both in h), the centre point 0.3 h
// from the edge on face A: whether it split, and the kernel's tilt from face A's normal.
std::pair<bool, double> split_at_edge(double rho, double sigma) {
  const std::vector<FitSample> nb = edge_samples(rho, 0.3, sigma, 7);
  std::vector<FitSample> copy = nb;
  KernelFit fit;
  EXPECT_TRUE(fit_samples(copy, Eigen::Vector3d::Zero(), kH, 8, 0.05, fit));
  EXPECT_GT(tilt_from_z(fit), 0.15);  // blended: tilted by more than 8 degrees
  PlaneRefit prm;
  prm.sigma = sigma;
  prm.crease_ratio = 1.1;
  EXPECT_TRUE(wants_split(fit, prm));
  const bool split = split_crease(nb, Eigen::Vector3d::Zero(), prm, fit);
  return {split, tilt_from_z(fit)};
}

TEST(PlaneRefitTest, TheCreaseSplitTakesSharpEdgesAndLeavesRoundedOnes) {
  // Sharp, and rounded with radius 0.05 h (within a few noise sigma): split, the kernel on
  // face A (within 1 degree).
  for (const double rho : {0.0, 0.05}) {
    const auto [split, tilt] = split_at_edge(rho, 0.02);
    EXPECT_TRUE(split) << rho;
    EXPECT_LT(tilt, 0.0175) << rho;
  }
  // Rounded with radius 0.3 h: two planes explain the samples to the noise (the wedge passes
  // the residual test at this noise), but face A's samples near the line follow the arc: no
  // split, the blended kernel left as it was.
  {
    const auto [split, tilt] = split_at_edge(0.3, 0.02);
    EXPECT_FALSE(split);
    EXPECT_GT(tilt, 0.15);
  }
  // At 2.5 times the noise the same rounding is lost in it: split.
  {
    const auto [split, tilt] = split_at_edge(0.3, 0.05);
    EXPECT_TRUE(split);
    EXPECT_LT(tilt, 0.05);
  }
}

}  // namespace
}  // namespace scanclean::detail

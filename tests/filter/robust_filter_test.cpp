#include "scanclean/filter/robust_filter.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <numeric>
#include <random>
#include <set>

#include "scanclean/core/errors.h"
#include "support/filter_outputs.h"
#include "support/synthetic.h"

namespace scanclean {
namespace {

double rms_z(const PointCloud& c) {
  double s = 0;
  for (const auto& p : c.positions) s += p.z() * p.z();
  return std::sqrt(s / static_cast<double>(std::max<std::size_t>(1, c.size())));
}

const Attribute& attr(const PointCloud& c, const std::string& name) {
  const Attribute* a = c.find_attribute(name);
  if (!a) throw std::runtime_error("missing attribute " + name);
  return *a;
}

// Input points in [first, end) (the injected ones) that no output point stands for.
std::size_t injected_removed(const FilterResult& r, std::size_t first, std::size_t end) {
  std::set<std::size_t> kept;
  for (double s : attr(r.cloud, "source_index").values) kept.insert(static_cast<std::size_t>(s));
  std::size_t n = 0;
  for (std::size_t i = first; i < end; ++i) n += kept.count(i) ? 0 : 1;
  return n;
}

// Output points that stand for an input point below `first` (the inliers, when the injected
// points were appended).
double kept_below(const FilterResult& r, std::size_t first) {
  std::size_t n = 0;
  for (double s : attr(r.cloud, "source_index").values) n += s < first ? 1 : 0;
  return static_cast<double>(n);
}

// Every input point is either in an output point's merge_count or in the outliers cloud, once.
void expect_accounting(const PointCloud& input, const FilterResult& r) {
  const auto& mc = attr(r.cloud, "merge_count").values;
  const double merged = std::accumulate(mc.begin(), mc.end(), 0.0);
  EXPECT_EQ(static_cast<std::size_t>(merged) + r.outliers.size(), input.size());
  EXPECT_EQ(r.stats.points_out, r.cloud.size());
  EXPECT_EQ(r.stats.unsupported + r.stats.off_surface + r.stats.low_density +
                r.stats.low_likelihood + r.stats.displaced + r.stats.small_components,
            r.outliers.size());
  EXPECT_EQ(r.stats.removed(), r.outliers.size());
  std::set<double> seen;
  for (double s : attr(r.cloud, "source_index").values) EXPECT_TRUE(seen.insert(s).second);
  for (double s : attr(r.outliers, "source_index").values) EXPECT_TRUE(seen.insert(s).second);
}

FilterOptions no_merge() {
  FilterOptions o;
  o.merge_eps = 0;
  return o;
}

TEST(RobustFilterTest, NoiseFreePlaneIsAFixedPoint) {
  PointCloud c = test::noisy_plane(5000, 1.0, 0.0, 1);  // seed 1
  c.normals.clear();                                    // PCA normals
  const FilterResult r = robust_filter(c, no_merge());
  // The likelihood-ratio test may take a few corner and rim points (one-sided support, L up to
  // 4x below their neighbours'); nothing else is removed, and nothing inside.
  EXPECT_EQ(r.stats.unsupported + r.stats.low_density + r.stats.small_components, 0u);
  EXPECT_LE(r.outliers.size(), c.size() / 200);
  for (double s : attr(r.outliers, "source_index").values) {
    const Eigen::Vector3d& p = c.positions[static_cast<std::size_t>(s)];
    EXPECT_LT(0.5 - std::max(std::abs(p.x()), std::abs(p.y())), r.stats.h) << p.transpose();
  }
  ASSERT_EQ(r.cloud.size() + r.outliers.size(), c.size());
  const auto& src = attr(r.cloud, "source_index").values;
  double max_move = 0;
  for (std::size_t k = 0; k < r.cloud.size(); ++k)
    max_move = std::max(
        max_move, (r.cloud.positions[k] - c.positions[static_cast<std::size_t>(src[k])]).norm());
  EXPECT_LT(max_move, 1e-6 * r.stats.h);
  EXPECT_EQ(r.stats.not_converged, 0u);
  expect_accounting(c, r);
}

TEST(RobustFilterTest, NoisyPlaneNoiseDropsThreeFold) {
  for (bool sensor : {false, true}) {
    PointCloud c = test::noisy_plane(20000, 1.0, 0.003, 2);  // seed 2
    if (!sensor) c.normals.clear();
    const FilterResult r = robust_filter(c, no_merge());
    const double before = rms_z(c), after = rms_z(r.cloud);
    EXPECT_LT(after * 3, before) << "sensor normals " << sensor << ": " << before << " -> "
                                 << after;
    EXPECT_GT(r.cloud.size(), 0.99 * c.size());
    EXPECT_LT(r.stats.mean_iterations, 10);
    expect_accounting(c, r);
  }
}

TEST(RobustFilterTest, NoisySphereKeepsItsRadius) {
  const double sigma = 0.01;
  PointCloud c = test::noisy_sphere(20000, 1.0, sigma, 3);  // seed 3
  c.normals.clear();
  const FilterResult r = robust_filter(c, no_merge());
  double sum_out = 0, dev_in = 0, dev_out = 0;
  for (const auto& p : c.positions) dev_in += std::pow(p.norm() - 1.0, 2);
  for (const auto& p : r.cloud.positions) {
    sum_out += p.norm();
    dev_out += std::pow(p.norm() - 1.0, 2);
  }
  const double bias = sum_out / r.cloud.size() - 1.0;
  EXPECT_LT(std::abs(bias), 0.25 * sigma) << "bias " << bias << " h " << r.stats.h;
  EXPECT_LT(std::sqrt(dev_out / r.cloud.size()) * 2, std::sqrt(dev_in / c.size()));
  EXPECT_GT(r.cloud.size(), 0.99 * c.size());
}

// RMS distance of the points to the sphere |p| = radius.
double rms_radial(const PointCloud& c, double radius) {
  double s = 0;
  for (const auto& p : c.positions) s += std::pow(p.norm() - radius, 2);
  return std::sqrt(s / static_cast<double>(std::max<std::size_t>(1, c.size())));
}

// The default tolerance, 1e-3 h (the spec's is 1e-4 h), stops each point near the maximum a far
// tighter one reaches: the same points kept, each within a small fraction of h of where the tight
// one leaves it, the surface as close to the sphere, in fewer steps.
TEST(RobustFilterTest, TheDefaultToleranceStopsNearTheTightOnesMaximum) {
  PointCloud c = test::noisy_sphere(20000, 1.0, 0.01, 3);  // seed 3
  c.normals.clear();
  const FilterOptions loose = no_merge();
  EXPECT_EQ(loose.tolerance, 1e-3);
  FilterOptions tight = no_merge();
  tight.tolerance = 1e-6;
  tight.max_iterations = 100;
  const FilterResult a = robust_filter(c, loose), b = robust_filter(c, tight);
  const auto in_b = test::by_source(b.cloud);
  std::size_t common = 0;
  double max_d = 0, sum_d2 = 0;
  for (const auto& [s, k] : test::by_source(a.cloud)) {
    const auto it = in_b.find(s);
    if (it == in_b.end()) continue;
    ++common;
    const double d = (a.cloud.positions[k] - b.cloud.positions[it->second]).norm();
    max_d = std::max(max_d, d);
    sum_d2 += d * d;
  }
  const double h = a.stats.h, rms_d = std::sqrt(sum_d2 / static_cast<double>(common));
  const double rms_a = rms_radial(a.cloud, 1.0), rms_b = rms_radial(b.cloud, 1.0);
  std::printf(
      "h %.4f: %zu / %zu / %zu points (loose / tight / both); moved by max %.2e h, RMS "
      "%.2e h; radial RMS %.6f / %.6f; steps %.2f / %.2f\n",
      h, a.cloud.size(), b.cloud.size(), common, max_d / h, rms_d / h, rms_a, rms_b,
      a.stats.mean_iterations, b.stats.mean_iterations);
  EXPECT_GT(common, a.cloud.size() - a.cloud.size() / 1000);
  EXPECT_GT(common, b.cloud.size() - b.cloud.size() / 1000);
  EXPECT_LT(rms_d, 1e-4 * h);  // measured: 7.5e-6 h (max 1.7e-4 h; 2.69 steps against 3.96)
  EXPECT_LT(max_d, 1e-3 * h);
  EXPECT_LT(std::abs(rms_a - rms_b), 0.01 * rms_b);
  EXPECT_LT(a.stats.mean_iterations, b.stats.mean_iterations);
}

TEST(RobustFilterTest, ScaleTestRaisesHOnFlatAndLowersItOnCurvedSurfaces) {
  FilterOptions noise_rule = no_merge();
  noise_rule.scale_gamma = 0;
  {
    // A plane has no curvature to bias a larger ball: h goes up the ladder, and less noise is
    // left (measured 0.0017 against 0.0029 at the noise rule's h).
    PointCloud c = test::noisy_plane(20000, 1.0, 0.01, 51);  // seed 51
    c.normals.clear();
    const FilterResult r = robust_filter(c, no_merge());
    const FilterResult n = robust_filter(c, noise_rule);
    EXPECT_GT(r.stats.h, 1.3 * r.stats.h_noise);
    EXPECT_EQ(n.stats.h, n.stats.h_noise);
    EXPECT_LT(rms_z(r.cloud), 0.8 * rms_z(n.cloud));
    expect_accounting(c, r);
  }
  {
    // A small sphere (radius 2x h_noise): the planes of larger balls shift with the curvature,
    // so h goes down. The filter's own bias there is smaller than the planes' (its kernels are
    // tangent around the point), so this costs accuracy on spheres (measured RMS 0.0015 against
    // 0.0009 at the noise rule's h; documented), but the noise still falls more than 5x.
    const double R = 0.1;
    PointCloud c = test::noisy_sphere(20000, R, 0.01, 52);  // seed 52
    c.normals.clear();
    const FilterResult r = robust_filter(c, no_merge());
    EXPECT_LT(r.stats.h, 0.8 * r.stats.h_noise);
    EXPECT_LT(rms_radial(r.cloud, R) * 5, rms_radial(c, R));
    EXPECT_GT(r.cloud.size(), 0.99 * c.size());
    expect_accounting(c, r);
  }
}

TEST(RobustFilterTest, DeterministicForAnyThreadCount) {
  PointCloud c = test::noisy_sphere(8000, 1.0, 0.01, 4);  // seed 4
  test::add_uniform_outliers(c, 300, -1.5, 1.5, 5);       // seed 5
  FilterOptions o;
  o.threads = 1;
  const FilterResult a = robust_filter(c, o);
  o.threads = 2;
  const FilterResult b = robust_filter(c, o);
  const FilterResult d = robust_filter(c, o);  // same thread count again: also identical
  ASSERT_EQ(a.cloud.size(), b.cloud.size());
  ASSERT_EQ(a.cloud.size(), d.cloud.size());
  for (std::size_t k = 0; k < a.cloud.size(); ++k) {
    ASSERT_EQ(a.cloud.positions[k], b.cloud.positions[k]) << k;
    ASSERT_EQ(a.cloud.positions[k], d.cloud.positions[k]) << k;
    ASSERT_EQ(a.cloud.normals[k], b.cloud.normals[k]) << k;
  }
  for (const auto& at : a.cloud.attributes)
    EXPECT_EQ(at.values, attr(b.cloud, at.name).values) << at.name;
  EXPECT_EQ(attr(a.outliers, "source_index").values, attr(b.outliers, "source_index").values);
  expect_accounting(c, a);
}

// Two parallel sheets z = 0 and z = gap, `n` points each, noise-free, sensor normals +z / -z
// (the second sheet faces the other way, as the two sides of a thin plate do).
PointCloud two_sheets(std::size_t n, double gap, std::uint32_t seed) {
  PointCloud a = test::noisy_plane(n, 1.0, 0.0, seed);
  PointCloud b = test::noisy_plane(n, 1.0, 0.0, seed + 1);
  for (auto& p : b.positions) p.z() = gap;
  for (auto& v : b.normals) v = Eigen::Vector3f(0, 0, -1);
  append(a, b);
  return a;
}

// Share of output points within `tol` of z = z0.
double share_near(const PointCloud& c, double z0, double tol) {
  std::size_t k = 0;
  for (const auto& p : c.positions) k += std::abs(p.z() - z0) < tol ? 1 : 0;
  return static_cast<double>(k) / static_cast<double>(std::max<std::size_t>(1, c.size()));
}

TEST(RobustFilterTest, UniformOutliersAreRemovedAndInliersKept) {
  PointCloud c = test::noisy_plane(20000, 1.0, 0.002, 6);  // seed 6
  c.normals.clear();
  const std::size_t inliers = c.size();
  const auto added = test::add_uniform_outliers(c, 1000, -0.5, 0.5, 7);  // seed 7: 5 %
  const FilterResult r = robust_filter(c, no_merge());
  std::set<std::size_t> removed;
  for (double s : attr(r.outliers, "source_index").values)
    removed.insert(static_cast<std::size_t>(s));
  // Recall over the outliers more than 10 noise sigma (0.02) off the plane; closer ones are
  // indistinguishable from noisy surface points.
  std::size_t far = 0, far_removed = 0;
  for (std::size_t i : added) {
    if (std::abs(c.positions[i].z()) < 0.02) continue;
    ++far;
    far_removed += removed.count(i);
  }
  std::size_t inliers_kept = 0;
  for (double s : attr(r.cloud, "source_index").values) inliers_kept += s < inliers ? 1 : 0;
  EXPECT_GT(far, 950u);
  EXPECT_GE(static_cast<double>(far_removed), 0.99 * far);
  EXPECT_GE(static_cast<double>(inliers_kept), 0.99 * inliers);
  EXPECT_GT(r.stats.unsupported + r.stats.low_density, 0u);
  expect_accounting(c, r);
}

TEST(RobustFilterTest, NoiseWiderThanTheNeighbourScaleRaisesH) {
  // 20k points on a unit square: the 96th neighbour lies about 0.04 away, about 2 sigma of the
  // noise (0.02). The scale must follow the noise (to about 5 sigma), and the noise fall.
  PointCloud c = test::noisy_plane(20000, 1.0, 0.02, 31);  // seed 31
  c.normals.clear();
  const FilterResult r = robust_filter(c, no_merge());
  EXPECT_GT(r.stats.h, 1.8 * r.stats.h0);
  EXPECT_GT(r.stats.noise_sigma, 0.7 * 0.02);              // measured at h, close to the truth
  EXPECT_LT(r.stats.noise_sigma_h0, r.stats.noise_sigma);  // biased low at h0
  EXPECT_LT(rms_z(r.cloud) * 4, rms_z(c)) << rms_z(r.cloud) << " vs " << rms_z(c);
  // The spec's literal rule (3 sigma measured at h0) leaves h at h0 and the noise high.
  FilterOptions spec = no_merge();
  spec.noise_factor = 3;
  spec.scale_gamma = 0;
  const FilterResult s = robust_filter(c, spec);
  EXPECT_EQ(s.stats.h, s.stats.h0);
  EXPECT_LT(rms_z(r.cloud), rms_z(s.cloud));
  expect_accounting(c, r);
  // h about 2x h0: kernels at every (h / h0)^2-th point; a kernel at every point is only
  // marginally smoother, and the thinned run is deterministic across thread counts too.
  EXPECT_GE(r.stats.kernel_stride, 3);
  EXPECT_LE(r.stats.kernels, c.size() / 3 + 1);
  FilterOptions all = no_merge();
  all.kernel_stride = 1;
  const FilterResult a = robust_filter(c, all);
  EXPECT_EQ(a.stats.kernel_stride, 1);
  EXPECT_LT(rms_z(r.cloud), 1.15 * rms_z(a.cloud));
  FilterOptions one = no_merge();
  one.threads = 1;
  const FilterResult r1 = robust_filter(c, one);
  ASSERT_EQ(r1.cloud.size(), r.cloud.size());
  for (std::size_t k = 0; k < r.cloud.size(); ++k)
    ASSERT_EQ(r1.cloud.positions[k], r.cloud.positions[k]) << k;
}

TEST(RobustFilterTest, OutliersCloserThanHAreRemoved) {
  // Outliers 0.3 h .. 0.9 h off a plane have surface kernels within reach and one of their own;
  // without the off-surface and likelihood-ratio tests they stay where they are. The tests
  // are checked one by one at the noise rule's h (scale test off: on this plane it would raise
  // h by 1.41 and thin the kernels to every 2nd point, and outliers without a kernel of their
  // own fall as unsupported), then all together with the defaults.
  PointCloud c = test::noisy_plane(20000, 1.0, 0.002, 32);  // seed 32
  c.normals.clear();
  const std::size_t inliers = c.size();
  FilterOptions base = no_merge();
  base.scale_gamma = 0;
  base.displacement_sigma = 0;  // these outliers keep their own mode: nothing to displace
  const double h_guess = robust_filter(c, base).stats.h;
  std::mt19937 rng(33);  // seed 33
  std::uniform_real_distribution<double> u(-0.4, 0.4), off(0.3, 0.9);
  for (int k = 0; k < 200; ++k) {
    const double z = (k % 2 ? 1 : -1) * off(rng) * h_guess, y = u(rng), x = u(rng);  // gcc's order
    c.positions.emplace_back(x, y, z);
  }
  auto removed = [&](const FilterResult& r) { return injected_removed(r, inliers, c.size()); };
  auto inliers_kept = [&](const FilterResult& r) { return kept_below(r, inliers); };
  // Each test alone, the density tests (tau, which also see these sparse points) off.
  FilterOptions neither = base;
  neither.likelihood_ratio = 0;
  neither.outlier_sigma = 0;
  neither.tau = 0;
  EXPECT_LT(removed(robust_filter(c, neither)), 100u);  // the failure the tests exist for
  FilterOptions off_surface_only = base;
  off_surface_only.likelihood_ratio = 0;
  off_surface_only.tau = 0;
  const FilterResult os = robust_filter(c, off_surface_only);
  EXPECT_GE(removed(os), 188u);  // 94 % (measured 192)
  EXPECT_GE(os.stats.off_surface, 170u);
  EXPECT_GE(inliers_kept(os), 0.995 * inliers);
  FilterOptions lr_only = base;
  lr_only.outlier_sigma = 0;
  lr_only.tau = 0;
  const FilterResult lr = robust_filter(c, lr_only);
  EXPECT_GT(lr.stats.low_likelihood, 100u);
  const FilterResult with = robust_filter(c, no_merge());
  EXPECT_GE(removed(with), 194u);  // 97 % (measured 196)
  EXPECT_GE(inliers_kept(with), 0.995 * inliers);
  expect_accounting(c, with);
}

TEST(RobustFilterTest, OutliersPulledOntoTheSurfaceAreRemovedByTheDisplacementTest) {
  // Outliers 5-10 sigma off a noisy sphere, too sparse for kernels of their own: the surface
  // kernels pull them onto the surface, where they end among the inliers' outputs with a
  // likelihood like theirs. Their move along the normal is 5-10x the inliers' spread, which is
  // what the displacement test looks at.
  const double sigma = 0.002;
  PointCloud c = test::noisy_sphere(20000, 0.3, sigma, 51);  // seed 51
  c.normals.clear();
  const std::size_t inliers = c.size();
  test::add_shell_outliers(c, 200, 0.3, 5 * sigma, 10 * sigma, 52);  // seed 52
  auto removed = [&](const FilterResult& r) { return injected_removed(r, inliers, c.size()); };
  auto inliers_kept = [&](const FilterResult& r) { return kept_below(r, inliers); };
  // The other tests off, so that the displacement test is measured alone.
  FilterOptions base = no_merge();
  base.likelihood_ratio = 0;
  base.outlier_sigma = 0;
  base.tau = 0;
  FilterOptions off_all = base;
  off_all.displacement_sigma = 0;
  const FilterResult none = robust_filter(c, off_all);
  EXPECT_LT(removed(none), 60u);  // unsupported only (measured 33)
  EXPECT_EQ(none.stats.displaced, 0u);
  const FilterResult d = robust_filter(c, base);  // displacement_sigma = 4 (default)
  EXPECT_GE(removed(d), 190u);                    // 95 % (measured 199)
  EXPECT_GE(d.stats.displaced, 150u);             // measured 168
  EXPECT_GE(inliers_kept(d), 0.999 * inliers);    // measured 19,996 of 20,000
  expect_accounting(c, d);
  // The defaults (every test on) do as well.
  const FilterResult all = robust_filter(c, no_merge());
  EXPECT_GE(removed(all), 190u);  // measured 200
  EXPECT_GE(inliers_kept(all), 0.999 * inliers);
}

TEST(RobustFilterTest, VolumetricClutterIsRemovedByTheSupportDensityTest) {
  // Dense uniform clutter (20 %) in a slab around a noisy plane, farther than 0.05 from it:
  // about 7 clutter points in an h-ball against the plane's 96, so the density test on the
  // output points keeps some of them (they collapse into clumps); their own kernels'
  // chi-weighted support is far below the plane's.
  PointCloud c = test::noisy_plane(10000, 1.0, 0.005, 41);  // seed 41
  c.normals.clear();
  const std::size_t inliers = c.size();
  std::mt19937 rng(42);  // seed 42
  std::uniform_real_distribution<double> u(-0.5, 0.5), z(-0.15, 0.15);
  while (c.size() < inliers + 2000) {
    const Eigen::Vector3d p = test::draw_point(rng, u, u, z);
    if (std::abs(p.z()) > 0.05) c.positions.push_back(p);
  }
  auto removed = [&](const FilterResult& r) { return injected_removed(r, inliers, c.size()); };
  auto inliers_kept = [&](const FilterResult& r) { return kept_below(r, inliers); };
  // At the noise rule's h (scale test off). Measured: all 2000 removed, 331 as low density;
  // without the support test 1993 and 217.
  FilterOptions at_noise_h = no_merge();
  at_noise_h.scale_gamma = 0;
  const FilterResult r = robust_filter(c, at_noise_h);
  EXPECT_EQ(removed(r), 2000u);
  EXPECT_GE(r.stats.low_density, 300u);
  EXPECT_GE(inliers_kept(r), 0.995 * inliers);
  expect_accounting(c, r);
  // The defaults: the scale test sees a flat surface and raises h by 1.41, nearer the clutter's
  // 0.05 gap. Measured: 1969 of 2000 removed (the known cost of the larger h).
  const FilterResult d = robust_filter(c, no_merge());
  EXPECT_GT(d.stats.h, 1.3 * d.stats.h_noise);
  EXPECT_GE(removed(d), 1960u);
  EXPECT_GE(inliers_kept(d), 0.995 * inliers);
  expect_accounting(c, d);
}

TEST(RobustFilterTest, SheetsAGapOfHApartStayApartAndCloserOnesMerge) {
  FilterOptions o = no_merge();
  o.scale = ScaleMode::kFixed;
  o.h = 0.05;
  o.use_sensor_normals = false;
  {
    const PointCloud c = two_sheets(6000, 1.0 * o.h, 8);  // seed 8
    const FilterResult r = robust_filter(c, o);
    EXPECT_GT(share_near(r.cloud, 0.0, 0.1 * o.h), 0.45);
    EXPECT_GT(share_near(r.cloud, o.h, 0.1 * o.h), 0.45);
    expect_accounting(c, r);
  }
  {
    const PointCloud c = two_sheets(6000, 0.3 * o.h, 9);  // seed 9
    const FilterResult r = robust_filter(c, o);
    // Collapsed into one layer about the middle (the documented limit).
    EXPECT_GT(share_near(r.cloud, 0.15 * o.h, 0.1 * o.h), 0.9);
    EXPECT_LT(share_near(r.cloud, 0.0, 0.03 * o.h), 0.1);
    EXPECT_LT(share_near(r.cloud, 0.3 * o.h, 0.03 * o.h), 0.1);
  }
}

TEST(RobustFilterTest, SensorNormalsKeepTheSidesOfAThinPlateApart) {
  FilterOptions o = no_merge();
  o.scale = ScaleMode::kFixed;
  o.h = 0.05;
  const PointCloud c = two_sheets(6000, 0.3 * o.h, 10);  // seed 10
  o.use_sensor_normals = true;
  const FilterResult with = robust_filter(c, o);
  EXPECT_GT(share_near(with.cloud, 0.0, 0.05 * o.h), 0.45);
  EXPECT_GT(share_near(with.cloud, 0.3 * o.h, 0.05 * o.h), 0.45);
  o.use_sensor_normals = false;
  const FilterResult without = robust_filter(c, o);
  EXPECT_LT(share_near(without.cloud, 0.0, 0.05 * o.h), 0.05);
}

TEST(RobustFilterTest, NormalsThatOnlyOrientKeepTheSidesApartAndFitTheirOwnPlanes) {
  // Two noisy sheets 0.3 h apart whose normals are estimates: each tilted by up to 25 degrees
  // from its sheet's outward normal (so that two of them still agree, dot > 0.5). As kernel
  // normals (the sensor-normal default) the tilts tilt the kernels' planes; with
  // normals_orient_only they only select the neighbours and orient the PCA normal, so the sheets
  // stay apart and the points land nearer their own sheet.
  FilterOptions o = no_merge();
  o.scale = ScaleMode::kFixed;
  o.h = 0.05;
  constexpr double kGap = 0.3 * 0.05, kSigma = 0.001;
  PointCloud c = test::noisy_plane(6000, 1.0, kSigma, 31);  // seed 31
  PointCloud b = test::noisy_plane(6000, 1.0, kSigma, 32);  // seed 32
  for (auto& p : b.positions) p.z() += kGap;
  for (auto& v : b.normals) v = Eigen::Vector3f(0, 0, -1);
  append(c, b);
  std::mt19937 rng(33);  // seed 33
  std::uniform_real_distribution<float> angle(0.0f, 25.0f * static_cast<float>(M_PI) / 180.0f),
      azimuth(0.0f, 2.0f * static_cast<float>(M_PI));
  for (auto& v : c.normals) {
    const float a = azimuth(rng);
    const Eigen::Vector3f axis(std::cos(a), std::sin(a), 0.0f);
    v = Eigen::AngleAxisf(angle(rng), axis) * v;
  }
  // RMS distance of the output points from the nearer sheet.
  auto rms_to_sheets = [&](const PointCloud& r) {
    double s = 0;
    for (const auto& p : r.positions) {
      const double d = std::min(std::abs(p.z()), std::abs(p.z() - kGap));
      s += d * d;
    }
    return std::sqrt(s / static_cast<double>(std::max<std::size_t>(1, r.size())));
  };
  EXPECT_FALSE(o.normals_orient_only);  // off by default: sensor normals are kernel normals
  const FilterResult as_kernel_normals = robust_filter(c, o);
  o.normals_orient_only = true;
  const FilterResult orienting = robust_filter(c, o);
  for (const FilterResult* r : {&as_kernel_normals, &orienting}) {
    EXPECT_GT(share_near(r->cloud, 0.0, 0.1 * kGap), 0.4);
    EXPECT_GT(share_near(r->cloud, kGap, 0.1 * kGap), 0.4);
    expect_accounting(c, *r);
  }
  // Measured: 0.00065 (tilted kernel normals) and 0.00030 (orienting only).
  const double tilted = rms_to_sheets(as_kernel_normals.cloud);
  const double own = rms_to_sheets(orienting.cloud);
  EXPECT_LT(own, 0.5 * kSigma);
  EXPECT_LT(own, 0.7 * tilted);
}

TEST(RobustFilterTest, AScalePerRegionShrinksHAtFineDetailAndKeepsItOnTheFlat) {
  // A noisy plane with a small sphere (radius 0.04) above one corner: the scale test picks
  // large balls on the plane and small ones at the sphere. One h for the cloud is the plane's;
  // with scale_regions the sphere's points get smaller h_i, and the sphere comes out truer.
  constexpr double kSigma = 0.002, kRadius = 0.04;
  const Eigen::Vector3d centre(-0.35, -0.35, 0.1);
  PointCloud c = test::noisy_plane(20000, 1.0, kSigma, 35);               // seed 35
  PointCloud ball = test::noisy_sphere(1500, kRadius, kSigma * 0.5, 36);  // seed 36
  for (auto& p : ball.positions) p += centre;
  append(c, ball);
  c.normals.clear();
  auto sphere_rms = [&](const PointCloud& r) {
    double s = 0;
    std::size_t n = 0;
    for (const auto& p : r.positions) {
      if ((p - centre).norm() > 2 * kRadius) continue;
      const double d = (p - centre).norm() - kRadius;
      s += d * d;
      ++n;
    }
    return std::sqrt(s / static_cast<double>(std::max<std::size_t>(1, n)));
  };
  FilterOptions o = no_merge();
  EXPECT_EQ(o.scale_regions, 0);  // off by default: one h
  const FilterResult one = robust_filter(c, o);
  EXPECT_EQ(one.stats.h_min, one.stats.h);
  EXPECT_EQ(one.stats.h_max, one.stats.h);
  o.scale_regions = 24;
  const FilterResult regions = robust_filter(c, o);
  // The plane holds most samples: the median h stays the plane's, the sphere's is smaller.
  EXPECT_NEAR(regions.stats.h, one.stats.h, 0.1 * one.stats.h);
  EXPECT_LT(regions.stats.h_min, 0.8 * regions.stats.h);
  EXPECT_LE(regions.stats.h_max, regions.stats.h * 1.5);
  // Measured: RMS distance to the sphere 0.00248 with one h, 0.00036 per region (h_i down to
  // 0.42 h there).
  EXPECT_LT(sphere_rms(regions.cloud), 0.5 * sphere_rms(one.cloud));
  expect_accounting(c, regions);
  // The same output for any thread count.
  o.threads = 1;
  const FilterResult serial = robust_filter(c, o);
  EXPECT_EQ(serial.cloud.positions, regions.cloud.positions);
  // Only with the automatic scale and its scale test.
  FilterOptions fixed = no_merge();
  fixed.scale = ScaleMode::kFixed;
  fixed.h = 0.05;
  fixed.scale_regions = 24;
  EXPECT_THROW(robust_filter(c, fixed), OptionError);
  FilterOptions no_test = no_merge();
  no_test.scale_gamma = 0;
  no_test.scale_regions = 24;
  EXPECT_THROW(robust_filter(c, no_test), OptionError);
}

TEST(RobustFilterTest, OwnPlaneRefitKeepsSheetsCloserThanHalfHApart) {
  // A noisy sheet with a second one 0.03 above a fifth of it (x < -0.3), without normals,
  // automatic h (the refit needs the noise estimate, which the single sheet sets): with the
  // refit (--refit-spread 1.2) each output point there stays on its own sheet; without it both
  // collapse onto the middle (the limit the refit removes).
  constexpr double kGap = 0.03, kSigma = 0.0008;
  PointCloud c = test::noisy_plane(6000, 1.0, kSigma, 12);  // seed 12
  PointCloud b = test::noisy_plane(6000, 1.0, kSigma, 13);  // seed 13
  PointCloud top;
  for (std::size_t i = 0; i < b.size(); ++i)
    if (b.positions[i].x() < -0.3)
      top.positions.push_back(b.positions[i] + Eigen::Vector3d(0, 0, kGap));
  append(c, top);
  c.normals.clear();
  FilterOptions o = no_merge();
  EXPECT_EQ(o.refit_spread, 0.0);  // off by default (its cost on large noisy clouds)
  o.refit_spread = 1.2;
  const FilterResult with = robust_filter(c, o);
  // Closer than 0.5 h (the regime where sheets collapsed), farther than the kernels' eigenvalue
  // floor resolves (3 x 0.05 h).
  ASSERT_GT(with.stats.h, 2 * kGap);
  ASSERT_LT(with.stats.h, kGap / 0.15);
  EXPECT_GT(with.stats.kernels_refitted, 0u);
  // Share of the output in the two-sheet strip (away from its border) within `tol` of z0.
  auto strip_share = [](const PointCloud& r, double z0, double tol) {
    std::size_t in = 0, near = 0;
    for (const auto& p : r.positions) {
      if (!(p.x() < -0.35 && p.x() > -0.45 && std::abs(p.y()) < 0.4)) continue;
      ++in;
      near += std::abs(p.z() - z0) < tol ? 1 : 0;
    }
    return static_cast<double>(near) / static_cast<double>(std::max<std::size_t>(1, in));
  };
  EXPECT_GT(strip_share(with.cloud, 0.0, 3 * kSigma), 0.4);
  EXPECT_GT(strip_share(with.cloud, kGap, 3 * kSigma), 0.4);
  expect_accounting(c, with);
  o.refit_spread = 0;
  const FilterResult without = robust_filter(c, o);
  EXPECT_EQ(without.stats.kernels_refitted, 0u);
  EXPECT_LT(strip_share(without.cloud, 0.0, 3 * kSigma), 0.1);
  EXPECT_LT(strip_share(without.cloud, kGap, 3 * kSigma), 0.1);
  // With sensor normals facing the same way on both sheets (one surface seen twice, as merged
  // scans registered apart), the refit leaves the kernels alone: they average the layers.
  PointCloud seen = c;
  seen.normals.assign(seen.size(), Eigen::Vector3f(0, 0, 1));
  o.refit_spread = 1.2;
  const FilterResult layers = robust_filter(seen, o);
  EXPECT_EQ(layers.stats.kernels_refitted, 0u);
  EXPECT_LT(strip_share(layers.cloud, 0.0, 3 * kSigma), 0.1);
  EXPECT_LT(strip_share(layers.cloud, kGap, 3 * kSigma), 0.1);
}

// A sharp 90-degree edge along y: face A z = 0 (x < 0) and face B x = 0 (z < 0), 1 x 0.5 each,
// noise sigma along each face's normal (seeded), no normals.
PointCloud sharp_edge(std::size_t n_face, double sigma, std::uint32_t seed) {
  const PointCloud a = test::noisy_plane(2 * n_face, 1.0, sigma, seed);
  const PointCloud b = test::noisy_plane(2 * n_face, 1.0, sigma, seed + 1);
  PointCloud c;
  for (const auto& p : a.positions)
    if (p.x() < 0) c.positions.push_back(p);
  for (const auto& p : b.positions)
    if (p.x() < 0) c.positions.emplace_back(p.z(), p.y(), p.x());
  return c;
}
// Distance from p to that edge's surface.
double edge_distance(const Eigen::Vector3d& p) {
  const double to_a = p.x() <= 0 ? std::abs(p.z()) : std::hypot(p.x(), p.z());
  const double to_b = p.z() <= 0 ? std::abs(p.x()) : std::hypot(p.x(), p.z());
  return std::min(to_a, to_b);
}
// RMS distance to that edge's surface of the output points within h of the edge line, away
// from the patch's ends (the band where blended kernels round the edge off).
double edge_band_rms(const FilterResult& r) {
  double sum = 0;
  std::size_t n = 0;
  for (const auto& p : r.cloud.positions) {
    if (!(std::hypot(p.x(), p.z()) < r.stats.h && std::abs(p.y()) < 0.4)) continue;
    const double d = edge_distance(p);
    sum += d * d;
    ++n;
  }
  EXPECT_GT(n, 100u);
  return std::sqrt(sum / static_cast<double>(std::max<std::size_t>(n, 1)));
}

TEST(RobustFilterTest, TheCreaseSplitKeepsASharpEdgeSharp) {
  constexpr double kSigma = 0.01;
  const PointCloud c = sharp_edge(6000, kSigma, 21);  // seeds 21, 22
  FilterOptions o = no_merge();
  EXPECT_EQ(o.crease_spread, 0.0);  // off by default (README, "Shapes at the known limits")
  o.crease_spread = 1.1;
  const FilterResult split = robust_filter(c, o);
  o.crease_spread = 0;
  const FilterResult blended = robust_filter(c, o);
  EXPECT_GT(split.stats.kernels_split, 100u);
  EXPECT_EQ(blended.stats.kernels_split, 0u);
  expect_accounting(c, split);
  const double rms_split = edge_band_rms(split), rms_blended = edge_band_rms(blended);
  std::printf("edge band RMS: split %.5f, blended %.5f (h %.4f, %zu kernels split)\n", rms_split,
              rms_blended, split.stats.h, split.stats.kernels_split);
  EXPECT_LT(rms_split, 0.7 * rms_blended);  // measured: 0.00188 against 0.00304 (h 0.074)
  // The same output for any thread count.
  FilterOptions serial = no_merge();
  serial.crease_spread = 1.1;
  serial.threads = 1;
  EXPECT_EQ(robust_filter(c, serial).cloud.positions, split.cloud.positions);
}

TEST(RobustFilterTest, WithTheScalePerRegionFacesBesideACreaseKeepTheirLargerH) {
  // The scale test's balls beside the crease take in the other face and stop early; with the
  // crease split on (and a scale per region) the test runs the ladder again on the sample's own
  // face (scale_selection.h, the crease test), and the faces near the edge keep the larger h
  // that their noise asks for.
  constexpr double kSigma = 0.015;
  const PointCloud c = sharp_edge(6000, kSigma, 23);  // seeds 23, 24
  FilterOptions o = no_merge();
  o.crease_spread = 1.1;
  o.scale_regions = 96;
  const FilterResult face = robust_filter(c, o);
  o.crease_spread = 0;
  const FilterResult plain = robust_filter(c, o);
  o.crease_spread = 1.1;
  o.scale_regions = 0;
  const FilterResult one_h = robust_filter(c, o);
  EXPECT_GT(face.stats.scale_crease_samples, 100u);
  EXPECT_EQ(plain.stats.scale_crease_samples, 0u);
  EXPECT_EQ(one_h.stats.scale_crease_samples, 0u);  // the test runs only per region
  expect_accounting(c, face);
  // RMS distance to the edge's surface of the output points away from the patch's borders.
  auto rms = [](const FilterResult& r) {
    double sum = 0;
    std::size_t n = 0;
    for (const auto& p : r.cloud.positions) {
      if (!(std::abs(p.y()) < 0.4 && p.x() > -0.4 && p.z() > -0.4)) continue;
      const double d = edge_distance(p);
      sum += d * d;
      ++n;
    }
    EXPECT_GT(n, 1000u);
    return std::sqrt(sum / static_cast<double>(std::max<std::size_t>(n, 1)));
  };
  const double r_face = rms(face), r_plain = rms(plain), r_one = rms(one_h);
  std::printf(
      "RMS: per region with the crease test %.5f (h %.4f .. %.4f, %zu samples), without "
      "%.5f (h %.4f .. %.4f), one h with the split %.5f (h %.4f)\n",
      r_face, face.stats.h_min, face.stats.h_max, face.stats.scale_crease_samples, r_plain,
      plain.stats.h_min, plain.stats.h_max, r_one, one_h.stats.h);
  // Measured: h 0.068 to 0.096 without the test, 0.096 everywhere with it (the one h of the
  // cloud with the split alone); RMS 0.00241 against 0.00190.
  EXPECT_GT(face.stats.h_min, plain.stats.h_min);
  EXPECT_LT(r_face, 0.9 * r_plain);
  // Not worse than one h with the split: here every region took the cloud's h, which the
  // regions hold in float and one h in double, so the two differ in the last digits (under the
  // sanitizers' build 0.00189964 against 0.00189964, the first larger).
  EXPECT_LE(r_face, r_one * (1 + 1e-4));
  // The same output for any thread count.
  FilterOptions serial = no_merge();
  serial.crease_spread = 1.1;
  serial.scale_regions = 96;
  serial.threads = 1;
  EXPECT_EQ(robust_filter(c, serial).cloud.positions, face.cloud.positions);
}

TEST(RobustFilterTest, TheSecondPassSplitsItsKernelsAtTheCreaseToo) {
  // The second pass fits its kernels to the first pass's output, whose spread across the
  // surface is a small part of the input's noise: its crease split is triggered against the
  // eigenvalue floor instead of the input's noise sigma (robust_filter.cpp, second_pass), so
  // that it keeps the edge the first pass kept. Against the input's sigma almost none of its
  // kernels asked for the split and the edge was rounded again.
  constexpr double kSigma = 0.015;
  const PointCloud c = sharp_edge(6000, kSigma, 25);  // seeds 25, 26
  FilterOptions o = no_merge();
  o.crease_spread = 1.1;
  const FilterResult one = robust_filter(c, o);
  o.passes = 2;
  const FilterResult two = robust_filter(c, o);
  expect_accounting(c, two);
  // kernels_split counts both passes.
  ASSERT_GE(two.stats.kernels_split, one.stats.kernels_split);
  const std::size_t second = two.stats.kernels_split - one.stats.kernels_split;
  const double rms_one = edge_band_rms(one), rms_two = edge_band_rms(two);
  std::printf("kernels split: first pass %zu, second %zu; edge band RMS: one pass %.5f, two %.5f\n",
              one.stats.kernels_split, second, rms_one, rms_two);
  EXPECT_GT(one.stats.kernels_split, 100u);
  EXPECT_GT(second, one.stats.kernels_split / 2);
  EXPECT_LT(rms_two, rms_one);
  // The same output for any thread count.
  o.threads = 1;
  EXPECT_EQ(robust_filter(c, o).cloud.positions, two.cloud.positions);
}

TEST(RobustFilterTest, ZeroWeightKernelsContributeNothing) {
  FilterOptions o = no_merge();
  o.scale = ScaleMode::kFixed;
  o.h = 0.05;
  o.use_sensor_normals = false;
  PointCloud c = two_sheets(5000, 1.2 * o.h, 11);  // seed 11
  // Sheet B (the second half) given weight 0: its kernels vanish, so its points lose all
  // support (sheet A is beyond the slab) and sheet A is filtered exactly as without B.
  c.confidences.assign(c.size(), 1.0f);
  for (std::size_t i = 5000; i < c.size(); ++i) c.confidences[i] = 0.0f;
  const FilterResult r = robust_filter(c, o);
  EXPECT_EQ(r.stats.unsupported, 5000u);
  for (double s : attr(r.cloud, "source_index").values) EXPECT_LT(s, 5000);
  PointCloud a = c;
  a.positions.resize(5000);
  a.normals.resize(5000);
  a.confidences.resize(5000);
  const FilterResult ra = robust_filter(a, o);
  ASSERT_EQ(ra.cloud.size(), r.cloud.size());
  for (std::size_t k = 0; k < r.cloud.size(); ++k)
    EXPECT_NEAR((ra.cloud.positions[k] - r.cloud.positions[k]).norm(), 0.0, 1e-6 * o.h);
  // With weight 1 the second sheet stays.
  c.confidences.assign(c.size(), 1.0f);
  EXPECT_LT(robust_filter(c, o).stats.unsupported, 10u);
  // Weights change the likelihood: half weights give half of L.
  a.confidences.assign(a.size(), 0.5f);
  const FilterResult half = robust_filter(a, o);
  EXPECT_NEAR(attr(half.cloud, "likelihood").values[0],
              0.5 * attr(ra.cloud, "likelihood").values[0],
              1e-4 * attr(ra.cloud, "likelihood").values[0]);
}

TEST(RobustFilterTest, AdaptiveKernelsHandleTenfoldDensityChange) {
  // Left half 10x denser than the right half; noise proportional to the local spacing.
  std::mt19937 rng(12);  // seed 12
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::normal_distribution<double> g(0.0, 1.0);
  PointCloud c;
  for (int i = 0; i < 20000; ++i) {
    const double z = 0.002 * g(rng), y = u(rng), x = -u(rng);  // gcc's order (test::draw_point)
    c.positions.emplace_back(x, y, z);
  }
  for (int i = 0; i < 2000; ++i) {
    const double z = 0.006 * g(rng), y = u(rng), x = u(rng);
    c.positions.emplace_back(x, y, z);
  }
  FilterOptions o = no_merge();
  o.scale = ScaleMode::kAdaptive;
  const FilterResult r = robust_filter(c, o);
  EXPECT_GT(r.stats.h_max, 2.5 * r.stats.h_min);
  double in_l = 0, in_r = 0, out_l = 0, out_r = 0;
  std::size_t nl = 0, nr = 0;
  for (const auto& p : c.positions) (p.x() < 0 ? in_l : in_r) += p.z() * p.z();
  for (const auto& p : r.cloud.positions) {
    if (std::abs(p.x()) < 0.15) continue;  // leave the density step aside
    (p.x() < 0 ? out_l : out_r) += p.z() * p.z();
    (p.x() < 0 ? nl : nr) += 1;
  }
  EXPECT_LT(std::sqrt(out_l / nl) * 3, std::sqrt(in_l / 20000));
  EXPECT_LT(std::sqrt(out_r / nr) * 3, std::sqrt(in_r / 2000));
  EXPECT_GT(r.cloud.size(), 0.98 * c.size());
  expect_accounting(c, r);
}

TEST(RobustFilterTest, DegenerateInputsGiveDocumentedResults) {
  {  // empty
    const FilterResult r = robust_filter(PointCloud{});
    EXPECT_EQ(r.cloud.size(), 0u);
    EXPECT_EQ(r.outliers.size(), 0u);
  }
  {  // all points equal: copies are one observation (input_groups.h), which no kernel supports
    PointCloud c;
    c.positions.assign(100, Eigen::Vector3d(1, 2, 3));
    const FilterResult r = robust_filter(c);
    EXPECT_EQ(r.cloud.size(), 0u);
    EXPECT_EQ(r.stats.unsupported, 100u);
    expect_accounting(c, r);
  }
  {  // collinear points stay on their line
    PointCloud c;
    for (int i = 0; i < 1000; ++i) c.positions.emplace_back(0.001 * i, 0.002 * i, 1.0);
    const FilterResult r = robust_filter(c, no_merge());
    EXPECT_GT(r.cloud.size(), 900u);
    for (const auto& p : r.cloud.positions) {
      EXPECT_NEAR(p.z(), 1.0, 1e-6);
      EXPECT_NEAR(p.y(), 2 * p.x(), 1e-6);
    }
    expect_accounting(c, r);
  }
  {  // fewer points than k_min: no kernels, everything unsupported
    PointCloud c = test::noisy_plane(5, 1.0, 0.0, 13);  // seed 13
    const FilterResult r = robust_filter(c);
    EXPECT_EQ(r.cloud.size(), 0u);
    EXPECT_EQ(r.outliers.size(), 5u);
    EXPECT_EQ(r.stats.unsupported, 5u);
    for (double f : attr(r.outliers, "flags").values) EXPECT_EQ(f, kFlagUnsupported);
  }
  {                                                       // NaN coordinate
    PointCloud c = test::noisy_plane(100, 1.0, 0.0, 14);  // seed 14
    c.positions[42].x() = std::numeric_limits<double>::quiet_NaN();
    try {
      robust_filter(c);
      ADD_FAILURE() << "no exception";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("point 42"), std::string::npos) << e.what();
    }
  }
  {                                                       // confidence outside [0, 1]
    PointCloud c = test::noisy_plane(100, 1.0, 0.0, 15);  // seed 15
    c.confidences.assign(100, 1.0f);
    c.confidences[7] = 2.0f;
    EXPECT_THROW(robust_filter(c), InputError);
  }
}

TEST(RobustFilterTest, ValidateRejectsEachBadOption) {
  EXPECT_NO_THROW(validate(FilterOptions{}));
  struct Case {
    std::string name;
    std::function<void(FilterOptions&)> set;
  };
  const std::vector<Case> cases = {
      {"h", [](FilterOptions& o) { o.scale = ScaleMode::kFixed; }},
      {"h", [](FilterOptions& o) { o.h = -1; }},
      {"h",
       [](FilterOptions& o) {
         o.scale = ScaleMode::kFixed;
         o.h = std::nan("");
       }},
      {"k_h", [](FilterOptions& o) { o.k_h = 1; }},
      {"k_adaptive", [](FilterOptions& o) { o.k_adaptive = 5000; }},
      {"k_min", [](FilterOptions& o) { o.k_min = 2; }},
      {"truncation_sigma", [](FilterOptions& o) { o.truncation_sigma = 0; }},
      {"slab", [](FilterOptions& o) { o.slab = -1; }},
      {"eigen_floor", [](FilterOptions& o) { o.eigen_floor = 2; }},
      {"tolerance", [](FilterOptions& o) { o.tolerance = 0; }},
      {"max_iterations", [](FilterOptions& o) { o.max_iterations = 0; }},
      {"max_iterations", [](FilterOptions& o) { o.max_iterations = 300; }},
      {"passes", [](FilterOptions& o) { o.passes = 3; }},
      {"merge_eps",
       [](FilterOptions& o) { o.merge_eps = std::numeric_limits<double>::infinity(); }},
      {"tau", [](FilterOptions& o) { o.tau = 1.5; }},
      {"tau", [](FilterOptions& o) { o.tau = -0.1; }},
      {"noise_factor", [](FilterOptions& o) { o.noise_factor = 0; }},
      {"kernel_stride", [](FilterOptions& o) { o.kernel_stride = -1; }},
      {"kernel_stride", [](FilterOptions& o) { o.kernel_stride = 65; }},
      {"noise_factor", [](FilterOptions& o) { o.noise_factor = 25; }},
      {"likelihood_ratio", [](FilterOptions& o) { o.likelihood_ratio = -0.5; }},
      {"likelihood_ratio", [](FilterOptions& o) { o.likelihood_ratio = 2; }},
      {"displacement_sigma", [](FilterOptions& o) { o.displacement_sigma = -1; }},
      {"displacement_sigma", [](FilterOptions& o) { o.displacement_sigma = 1e9; }},
      {"refit_spread", [](FilterOptions& o) { o.refit_spread = -0.5; }},
      {"refit_spread", [](FilterOptions& o) { o.refit_spread = std::nan(""); }},
      {"refit_noise_sigma", [](FilterOptions& o) { o.refit_noise_sigma = -0.01; }},
      {"refit_noise_sigma", [](FilterOptions& o) { o.refit_noise_sigma = INFINITY; }},
      {"threads", [](FilterOptions& o) { o.threads = -1; }},
      {"min_component_size", [](FilterOptions& o) { o.min_component_size = 10000000000ULL; }},
  };
  for (const auto& c : cases) {
    FilterOptions o;
    c.set(o);
    try {
      validate(o);
      ADD_FAILURE() << c.name << " accepted";
    } catch (const OptionError& e) {
      EXPECT_NE(std::string(e.what()).find(c.name), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("expected"), std::string::npos) << e.what();
    }
    EXPECT_THROW(robust_filter(test::noisy_plane(10, 1, 0, 1), o), OptionError);
  }
}

TEST(RobustFilterTest, VectorUpdateAlsoConvergesOnThePlane) {
  PointCloud c = test::noisy_plane(10000, 1.0, 0.003, 16);  // seed 16
  c.normals.clear();
  FilterOptions o = no_merge();
  o.update = UpdateMode::kVector;
  const FilterResult r = robust_filter(c, o);
  EXPECT_LT(rms_z(r.cloud) * 3, rms_z(c));
  EXPECT_LT(r.stats.not_converged, c.size() / 20);
  EXPECT_LT(r.stats.mean_iterations, 10);
  expect_accounting(c, r);
}

TEST(RobustFilterTest, ClusteringMergesAndCountsMembers) {
  PointCloud c = test::noisy_plane(6000, 1.0, 0.002, 17);  // seed 17
  c.normals.clear();
  FilterOptions o;
  o.merge_eps = -1;  // default 0.25 s
  const FilterResult def = robust_filter(c, o);
  EXPECT_NEAR(def.stats.merge_eps, 0.25 * def.stats.mean_spacing, 1e-12);
  o.merge_eps = 0.6 * def.stats.mean_spacing;
  const FilterResult r = robust_filter(c, o);
  EXPECT_LT(r.cloud.size(), def.cloud.size());
  EXPECT_LT(r.cloud.size(), 0.9 * c.size());
  EXPECT_GT(r.stats.merged, 0u);
  const auto& mc = attr(r.cloud, "merge_count").values;
  EXPECT_GT(*std::max_element(mc.begin(), mc.end()), 1);
  expect_accounting(c, r);
  expect_accounting(c, def);
  // No two representatives closer than eps can both come from converged, mergeable points...
  // ...but each representative is within eps of its seed's projection (non-chaining).
  EXPECT_EQ(r.stats.merged, c.size() - r.cloud.size() - r.outliers.size());
}

TEST(RobustFilterTest, SecondPassKeepsAccountingAndSmoothsFurther) {
  PointCloud c = test::noisy_plane(6000, 1.0, 0.004, 18);  // seed 18
  c.normals.clear();
  FilterOptions o = no_merge();
  const FilterResult one = robust_filter(c, o);
  o.passes = 2;
  const FilterResult two = robust_filter(c, o);
  EXPECT_LT(rms_z(two.cloud), rms_z(one.cloud) * 1.05);
  EXPECT_LT(rms_z(two.cloud) * 3, rms_z(c));
  expect_accounting(c, two);
}

TEST(RobustFilterTest, SmallComponentsAreRemovedOnRequest) {
  PointCloud c = test::noisy_plane(10000, 1.0, 0.001, 19);  // seed 19
  c.normals.clear();
  // A tight clump of 20 points far from the plane: dense enough for its own kernels (k_min 8)
  // and for the density test (tau x median density is about 10 input points at K_h = 96), but
  // a component smaller than the requested 30 points.
  std::mt19937 rng(20);  // seed 20
  std::normal_distribution<double> g(0.0, 0.002);
  for (int i = 0; i < 20; ++i) {
    const double z = 0.4 + 0.0001 * g(rng), y = g(rng), x = g(rng);  // gcc's order
    c.positions.emplace_back(x, y, z);
  }
  FilterOptions o = no_merge();
  const FilterResult keep = robust_filter(c, o);
  std::size_t clump_kept = 0;
  for (const auto& p : keep.cloud.positions) clump_kept += p.z() > 0.3 ? 1 : 0;
  EXPECT_EQ(clump_kept, 20u);
  o.remove_small_components = true;
  o.min_component_size = 30;
  const FilterResult drop = robust_filter(c, o);
  for (const auto& p : drop.cloud.positions) EXPECT_LT(p.z(), 0.3);
  EXPECT_EQ(drop.stats.small_components, 20u);
  expect_accounting(c, drop);
}

}  // namespace
}  // namespace scanclean

namespace scanclean {
namespace {

TEST(RobustFilterTest, OrientKGivesACloudWithoutNormalsConsistentOnes) {
  // A noisy sphere without normals: with orient_k every point first gets a normal oriented over
  // the neighbour graph (one tree, outwards: its top point faces up), and the output normals
  // follow them; without, the kernels' PCA normals take either sign. The points are as close to
  // the sphere either way (on a closed smooth surface the orientation keeps every neighbour).
  const PointCloud sphere = test::noisy_sphere(20000, 1.0, 0.01, 45);  // seed 45
  PointCloud bare = sphere;
  bare.normals.clear();
  FilterOptions o;
  o.threads = 2;
  const FilterResult plain = robust_filter(bare, o);
  o.orient_k = 48;
  const FilterResult oriented = robust_filter(bare, o);
  EXPECT_EQ(plain.stats.orientation_trees, 0u);
  EXPECT_EQ(oriented.stats.orientation_trees, 1u);
  EXPECT_GT(oriented.stats.seconds_orientation, 0.0);
  auto outward = [](const PointCloud& c) {
    std::size_t n = 0;
    for (std::size_t i = 0; i < c.size(); ++i)
      n += c.normals[i].cast<double>().dot(c.positions[i]) > 0 ? 1 : 0;
    return static_cast<double>(n) / static_cast<double>(std::max<std::size_t>(1, c.size()));
  };
  auto rms_radius = [](const PointCloud& c) {
    double s = 0;
    for (const auto& p : c.positions) s += (p.norm() - 1) * (p.norm() - 1);
    return std::sqrt(s / static_cast<double>(std::max<std::size_t>(1, c.size())));
  };
  const double plain_share = outward(plain.cloud);
  EXPECT_GT(std::min(plain_share, 1 - plain_share), 0.1) << plain_share;
  EXPECT_GT(outward(oriented.cloud), 0.999);
  EXPECT_LT(rms_radius(oriented.cloud), 1.02 * rms_radius(plain.cloud));
  // The same for one thread, bit for bit.
  o.threads = 1;
  const FilterResult one = robust_filter(bare, o);
  ASSERT_EQ(one.cloud.size(), oriented.cloud.size());
  for (std::size_t i = 0; i < one.cloud.size(); ++i) {
    ASSERT_EQ(one.cloud.positions[i], oriented.cloud.positions[i]) << i;
    ASSERT_EQ(one.cloud.normals[i], oriented.cloud.normals[i]) << i;
  }
  // Input normals take precedence: no orientation then.
  o.threads = 2;
  EXPECT_EQ(robust_filter(sphere, o).stats.orientation_trees, 0u);
  // Out of range.
  o.orient_k = kMinOrientK - 1;
  EXPECT_THROW(robust_filter(bare, o), OptionError);
  // A viewpoint inside the sphere: every output normal faces it, inwards. A viewpoint needs
  // orient_k, and finite coordinates.
  o.orient_k = 48;
  o.orient_viewpoint = std::array<double, 3>{0.0, 0.0, 0.0};
  const FilterResult inward = robust_filter(bare, o);
  EXPECT_EQ(inward.stats.orientation_trees, 0u);
  EXPECT_LT(outward(inward.cloud), 0.001);
  EXPECT_LT(rms_radius(inward.cloud), 1.02 * rms_radius(plain.cloud));
  o.orient_viewpoint = std::array<double, 3>{0.0, NAN, 0.0};
  EXPECT_THROW(robust_filter(bare, o), OptionError);
  o.orient_viewpoint = std::array<double, 3>{0.0, 0.0, 0.0};
  o.orient_k = 0;
  EXPECT_THROW(robust_filter(bare, o), OptionError);
}

}  // namespace
}  // namespace scanclean

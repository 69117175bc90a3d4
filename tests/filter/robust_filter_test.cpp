#include "scanclean/filter/robust_filter.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>
#include <set>

#include "scanclean/core/errors.h"
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

// Every input point is either in an output point's merge_count or in the outliers cloud, once.
void expect_accounting(const PointCloud& input, const FilterResult& r) {
  const auto& mc = attr(r.cloud, "merge_count").values;
  const double merged = std::accumulate(mc.begin(), mc.end(), 0.0);
  EXPECT_EQ(static_cast<std::size_t>(merged) + r.outliers.size(), input.size());
  EXPECT_EQ(r.stats.points_out, r.cloud.size());
  EXPECT_EQ(r.stats.unsupported + r.stats.low_density + r.stats.small_components,
            r.outliers.size());
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
  ASSERT_EQ(r.cloud.size(), c.size());
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
  double sum_in = 0, sum_out = 0, dev_in = 0, dev_out = 0;
  for (const auto& p : c.positions) {
    sum_in += p.norm();
    dev_in += std::pow(p.norm() - 1.0, 2);
  }
  for (const auto& p : r.cloud.positions) {
    sum_out += p.norm();
    dev_out += std::pow(p.norm() - 1.0, 2);
  }
  const double bias = sum_out / r.cloud.size() - 1.0;
  EXPECT_LT(std::abs(bias), 0.25 * sigma) << "bias " << bias << " h " << r.stats.h;
  EXPECT_LT(std::sqrt(dev_out / r.cloud.size()) * 2, std::sqrt(dev_in / c.size()));
  EXPECT_GT(r.cloud.size(), 0.99 * c.size());
}

TEST(RobustFilterTest, DeterministicForAnyThreadCount) {
  PointCloud c = test::noisy_sphere(15000, 1.0, 0.01, 4);  // seed 4
  test::add_uniform_outliers(c, 500, -1.5, 1.5, 5);        // seed 5
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

}  // namespace
}  // namespace scanclean

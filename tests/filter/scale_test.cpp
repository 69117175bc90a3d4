// The scale phase (filter/src/scale.h): per-point h_i against the k-th neighbour distance by
// brute force (the oracle), the fixed h, and the automatic h0 against the brute-force median.

#include "../../filter/src/scale.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "scanclean/core/errors.h"
#include "scanclean/filter/robust_filter.h"
#include "support/synthetic.h"

namespace scanclean::detail {
namespace {

struct Input {
  PointSet in;
  std::vector<Eigen::Vector3f> pf;
};

Input input_of(const PointCloud& c) {
  Input x;
  for (const auto& p : c.positions) {
    x.in.p.push_back(p);
    x.pf.push_back(p.cast<float>());
  }
  return x;
}

// Distance from point i to its k-th nearest other point, in float as the index measures.
double kth_distance(const std::vector<Eigen::Vector3f>& pf, std::size_t i, int k) {
  std::vector<float> d;
  for (std::size_t j = 0; j < pf.size(); ++j)
    if (j != i) d.push_back((pf[j] - pf[i]).squaredNorm());
  std::nth_element(d.begin(), d.begin() + (k - 1), d.end());
  return std::sqrt(static_cast<double>(d[k - 1]));
}

TEST(ScaleTest, AdaptiveKernelSizesAreTheKthNeighbourDistances) {
  // Two densities, so that h_i varies tenfold.
  PointCloud c = test::noisy_plane(1500, 0.1, 0.0002, 61);
  PointCloud sparse = test::noisy_plane(150, 0.1, 0.0002, 62);
  for (auto& p : sparse.positions) p.x() += 0.1;
  append(c, sparse);
  Input x = input_of(c);
  FilterOptions o;
  o.scale = ScaleMode::kAdaptive;
  o.k_adaptive = 20;
  const ScaleChoice s = choose_scale(x.in, x.pf, 0.3, false, o);
  ASSERT_EQ(x.in.hi.size(), x.pf.size());
  // Every point: most are found in the band around their cell's last distance, the first of a
  // cell and the rest by the full search (scale.cpp).
  for (std::size_t i = 0; i < x.pf.size(); ++i)
    EXPECT_NEAR(x.in.hi[i], kth_distance(x.pf, i, o.k_adaptive), 1e-7) << i;
  std::vector<float> sorted = x.in.hi;
  std::nth_element(sorted.begin(), sorted.begin() + (sorted.size() - 1) / 2, sorted.end());
  EXPECT_EQ(s.h, static_cast<double>(sorted[(sorted.size() - 1) / 2]));
  EXPECT_EQ(s.h_min, *std::min_element(x.in.hi.begin(), x.in.hi.end()));
  EXPECT_GT(s.h_max, 2.5 * s.h_min);
  EXPECT_EQ(x.in.h, s.h);
  // The grids are sized for the 99th percentile of h_i, within [h, 1.7 h]: here the sparse
  // part's h_i, far above the median, so 1.7 h.
  std::vector<float> q = x.in.hi;
  const std::size_t p99 = (q.size() - 1) * 99 / 100;
  std::nth_element(q.begin(), q.begin() + static_cast<std::ptrdiff_t>(p99), q.end());
  EXPECT_GT(q[p99], 1.7 * s.h);
  EXPECT_DOUBLE_EQ(s.h_grid, 1.7 * s.h);
}

TEST(ScaleTest, GridsAreSizedForHighPercentilesOfTheAdaptiveSizes) {
  // One density with a few far points: the 99th percentile lies between h and 1.7 h.
  PointCloud c = test::noisy_plane(3000, 0.1, 0.002, 64);
  Input x = input_of(c);
  FilterOptions o;
  o.scale = ScaleMode::kAdaptive;
  o.k_adaptive = 30;
  const ScaleChoice s = choose_scale(x.in, x.pf, 0.15, false, o);
  std::vector<float> q = x.in.hi;
  const std::size_t p99 = (q.size() - 1) * 99 / 100;
  std::nth_element(q.begin(), q.begin() + static_cast<std::ptrdiff_t>(p99), q.end());
  const double want = std::clamp(static_cast<double>(q[p99]), s.h, 1.7 * s.h);
  EXPECT_EQ(s.h_grid, want);
  EXPECT_GT(s.h_grid, s.h);
  // The kernel centres' grid: the 99.9th percentile, within [h_grid, 1.7 h].
  const std::size_t p999 = (q.size() - 1) * 999 / 1000;
  std::nth_element(q.begin(), q.begin() + static_cast<std::ptrdiff_t>(p999), q.end());
  EXPECT_EQ(s.h_grid_kernels, std::clamp(static_cast<double>(q[p999]), s.h_grid, 1.7 * s.h));
  EXPECT_GT(s.h_grid_kernels, s.h_grid);
  // One h: the grids are sized for it.
  Input y = input_of(c);
  FilterOptions fixed;
  fixed.scale = ScaleMode::kFixed;
  fixed.h = 0.01;
  const ScaleChoice f = choose_scale(y.in, y.pf, 0.15, false, fixed);
  EXPECT_EQ(f.h_grid, 0.01);
  EXPECT_EQ(f.h_grid_kernels, 0.01);
}

TEST(ScaleTest, FixedScaleIsTakenAsGiven) {
  Input x = input_of(test::noisy_plane(500, 0.1, 0.0002, 63));
  FilterOptions o;
  o.scale = ScaleMode::kFixed;
  o.h = 0.0123;
  const ScaleChoice s = choose_scale(x.in, x.pf, 0.15, false, o);
  EXPECT_EQ(s.h, 0.0123);
  EXPECT_EQ(s.h_min, 0.0123);
  EXPECT_EQ(s.h_max, 0.0123);
  EXPECT_TRUE(x.in.hi.empty());
}

TEST(ScaleTest, AutomaticH0IsTheMedianKthNeighbourDistance) {
  Input x = input_of(test::noisy_plane(3000, 0.1, 0.0, 64));  // noise-free: h stays near h0
  FilterOptions o;
  o.scale_gamma = 0;  // the noise rule alone
  const ScaleChoice s = choose_scale(x.in, x.pf, 0.15, false, o);
  std::vector<double> kd;
  for (std::size_t i = 0; i < x.pf.size(); ++i) kd.push_back(kth_distance(x.pf, i, o.k_h));
  std::nth_element(kd.begin(), kd.begin() + (kd.size() - 1) / 2, kd.end());
  // Under 10,000 points every point is sampled: h0 is the exact median.
  EXPECT_NEAR(s.h0, kd[(kd.size() - 1) / 2], 1e-7);
  EXPECT_NEAR(s.noise_sigma, 0.0, 1e-6);
  EXPECT_EQ(s.h, s.h0);  // no noise to raise it
}

// On a noisy plane the scale test takes its largest ball, so h is that radius and its grid
// (cells of 1.001 h) is the one the later phases want: it is handed on, and it is the very grid
// they would have built (the same slots). On a small sphere the test takes a smaller ball, and
// no grid of other cells is handed on (it would move the thinned kernels' sites).
TEST(ScaleTest, TheScaleTestsGridIsHandedOnOnlyWhenItIsTheGridWanted) {
  {
    Input x = input_of(test::noisy_plane(20000, 1.0, 0.02, 68));
    FilterOptions o;
    const ScaleChoice s = choose_scale(x.in, x.pf, 1.5, false, o);
    ASSERT_GT(s.h, 1.3 * s.h_noise);  // the largest ball, sqrt(2) h_noise
    ASSERT_NE(s.index, nullptr);
    EXPECT_EQ(s.index->cell(), s.h_grid * 1.001);
    const NeighborIndex fresh(x.pf, s.h_grid * 1.001);
    EXPECT_EQ(s.index->order(), fresh.order());
    ASSERT_EQ(s.index->cell_count(), fresh.cell_count());
    for (std::size_t c = 0; c <= fresh.cell_count(); ++c)
      ASSERT_EQ(s.index->cell_begin(c), fresh.cell_begin(c)) << c;
  }
  {
    Input x = input_of(test::noisy_sphere(20000, 0.05, 0.003, 69));
    FilterOptions o;
    const ScaleChoice s = choose_scale(x.in, x.pf, 0.18, false, o);
    ASSERT_LT(s.h, 1.3 * s.h_noise);  // a smaller ball than the largest
    const double test_cell = s.h_noise * std::pow(2.0, 2 / 4.0) * 1.001;  // noise_scale.cpp
    ASSERT_LE(test_cell, s.h_grid * 1.7);  // within the range a grid may serve in
    if (s.index) {
      EXPECT_NE(s.index->cell(), test_cell);
      EXPECT_GE(s.index->cell(), s.h_grid * 1.001);
      EXPECT_LE(s.index->cell(), s.h_grid * 1.7);
    }
  }
}

// The median K-th neighbour distance stays exact when part of the samples, far sparser than the
// rest, stop their search at the grid's reach (scale.cpp): a minority (the median lies among the
// dense samples) and a majority (the sparse ones must then be searched to the end).
TEST(ScaleTest, AutomaticH0IsExactWithSparsePartsBeyondTheGridsReach) {
  for (const auto& [dense, sparse] : {std::pair{3000, 300}, std::pair{600, 3000}}) {
    PointCloud c = test::noisy_plane(dense, 0.1, 0.0, 65);
    PointCloud far = test::noisy_plane(sparse, sparse == 300 ? 0.1 : 0.6, 0.0, 66);
    for (auto& p : far.positions) p.x() += 0.8;
    append(c, far);
    Input x = input_of(c);
    FilterOptions o;
    o.scale_gamma = 0;
    const ScaleChoice s = choose_scale(x.in, x.pf, 1.0, false, o);
    std::vector<double> kd;
    for (std::size_t i = 0; i < x.pf.size(); ++i) kd.push_back(kth_distance(x.pf, i, o.k_h));
    std::nth_element(kd.begin(), kd.begin() + (kd.size() - 1) / 2, kd.end());
    EXPECT_NEAR(s.h0, kd[(kd.size() - 1) / 2], 1e-7) << dense << " + " << sparse;
  }
}

// A fixed h that puts most of the cloud within h of a point (a mistyped --h) is refused before
// the kernels; one whose neighbourhoods hold 50 or 1,250 points is not.
TEST(ScaleTest, AFixedHHoldingTooManyNeighboursIsRefused) {
  const PointCloud c = test::noisy_plane(40000, 1.0, 0.0, 67);
  std::vector<Eigen::Vector3f> pf;
  for (const auto& p : c.positions) pf.push_back(p.cast<float>());
  for (const double h : {0.02, 0.1}) {
    const NeighborIndex index(pf, h * 1.001);
    EXPECT_NO_THROW(check_fixed_scale(index, h)) << h;
  }
  for (const double h : {1.0, 10.0}) {
    const NeighborIndex index(pf, h * 1.001);
    try {
      check_fixed_scale(index, h);
      ADD_FAILURE() << "h " << h << " was not refused";
    } catch (const OptionError& e) {
      EXPECT_NE(std::string(e.what()).find("at most 20000"), std::string::npos) << e.what();
    }
  }
  // Through the filter: refused before any work.
  FilterOptions o;
  o.scale = ScaleMode::kFixed;
  o.h = 10.0;
  EXPECT_THROW(robust_filter(c, o), OptionError);
}

}  // namespace
}  // namespace scanclean::detail

// Coincident and far points (filter/src/input_groups.h): the filter's answer on a cloud with
// copies of its points, or with stray points far away, is its answer on the cloud without them;
// the copies follow their point, the far points are filtered on their own.

#include "../../filter/src/input_groups.h"

#include <gtest/gtest.h>

#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <tuple>

#include "scanclean/filter/robust_filter.h"
#include "support/synthetic.h"

namespace scanclean {
namespace {

const Attribute& attr(const PointCloud& c, const std::string& name) {
  const Attribute* a = c.find_attribute(name);
  EXPECT_NE(a, nullptr) << name;
  static const Attribute none;
  return a ? *a : none;
}

std::size_t total_merge_count(const FilterResult& r) {
  double sum = 0;
  for (double v : attr(r.cloud, "merge_count").values) sum += v;
  return static_cast<std::size_t>(sum);
}

TEST(InputGroupsTest, CoincidentGroupsMatchAMapOfPositions) {
  // Oracle: a std::map from the coordinates (with -0 as +0) to the first index there. Many
  // points, some copied (also as -0 and +0), in 1 and 2 threads.
  std::mt19937 rng(57);  // seed 57
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  PointCloud c;
  for (int i = 0; i < 200000; ++i) {
    if (i > 0 && i % 7 == 0) {
      c.positions.push_back(c.positions[rng() % c.positions.size()]);
    } else {
      const double z = i % 11 == 0 ? 0.0 : u(rng), y = u(rng), x = u(rng);  // gcc's order
      const Eigen::Vector3d p(x, y, z);
      c.positions.push_back(p);
    }
    if (i % 13 == 0) c.positions.push_back({c.positions.back().x(), c.positions.back().y(), -0.0});
  }
  std::map<std::tuple<double, double, double>, std::size_t> first;
  std::vector<std::size_t> want_first(c.size());
  for (std::size_t i = 0; i < c.size(); ++i) {
    const Eigen::Vector3d& p = c.positions[i];
    auto key = std::make_tuple(p.x() + 0.0, p.y() + 0.0, p.z() + 0.0);
    want_first[i] = first.emplace(key, i).first->second;
  }
  for (const int threads : {1, 2}) {
    tbb::task_arena arena(threads);
    detail::Coincident got;
    arena.execute([&] { got = detail::find_coincident(c); });
    ASSERT_TRUE(got.any());
    ASSERT_EQ(got.first.size(), first.size());
    std::vector<std::uint32_t> count(got.first.size(), 0);
    for (std::size_t i = 0; i < c.size(); ++i) {
      ASSERT_EQ(got.first[got.group_of[i]], want_first[i]) << i;
      ++count[got.group_of[i]];
    }
    EXPECT_EQ(count, got.count);
    EXPECT_TRUE(std::is_sorted(got.first.begin(), got.first.end()));
  }
  // No copies: nothing held.
  PointCloud distinct;
  for (int i = 0; i < 1000; ++i) distinct.positions.push_back({u(rng), u(rng), u(rng)});
  EXPECT_FALSE(detail::find_coincident(distinct).any());
  // No points, and one.
  EXPECT_FALSE(detail::find_coincident(PointCloud{}).any());
  PointCloud one;
  one.positions.push_back({0.5, -0.25, 2.0});
  EXPECT_FALSE(detail::find_coincident(one).any());
}

TEST(InputGroupsTest, CoincidentCopiesFollowTheirPoint) {
  const PointCloud plane = test::noisy_plane(2000, 0.2, 0.001, 51);
  // Every point 25 times, copies interleaved, plus 3 stray points (so some copies are removed).
  PointCloud base = plane;
  test::add_uniform_outliers(base, 3, -0.1, 0.1, 52);
  PointCloud copies;
  std::vector<std::size_t> order;
  for (int k = 0; k < 25; ++k)
    for (std::size_t i = 0; i < base.size(); ++i) order.push_back(i);
  copies = select(base, order);
  const FilterResult one = robust_filter(base);
  const FilterResult many = robust_filter(copies);
  EXPECT_EQ(many.stats.h, one.stats.h);  // copies do not shrink the automatic scale
  ASSERT_EQ(many.cloud.size(), one.cloud.size());
  for (std::size_t k = 0; k < one.cloud.size(); ++k) {
    EXPECT_EQ(many.cloud.positions[k], one.cloud.positions[k]) << k;
    EXPECT_EQ(attr(many.cloud, "source_index").values[k],
              attr(one.cloud, "source_index").values[k]);
    EXPECT_EQ(attr(many.cloud, "merge_count").values[k],
              25 * attr(one.cloud, "merge_count").values[k]);
  }
  EXPECT_EQ(many.outliers.size(), 25 * one.outliers.size());
  EXPECT_EQ(total_merge_count(many) + many.outliers.size(), copies.size());
  EXPECT_EQ(many.stats.removed(), 25 * one.stats.removed());
  EXPECT_EQ(many.stats.points_in, copies.size());
  // Every removed copy carries its point's flags and its own input index.
  const auto& si = attr(many.outliers, "source_index").values;
  for (std::size_t k = 0; k + 1 < si.size(); ++k) EXPECT_LT(si[k], si[k + 1]);
}

TEST(InputGroupsTest, ManyPointsAtOnePositionAreOneUnsupportedPoint) {
  PointCloud c;
  c.positions.assign(100000, Eigen::Vector3d(1.5, -2, 0.25));
  const FilterResult r = robust_filter(c);  // was quadratic: every copy every other's neighbour
  EXPECT_EQ(r.cloud.size(), 0u);
  EXPECT_EQ(r.stats.unsupported, c.size());
  EXPECT_EQ(r.outliers.size(), c.size());
}

void expect_same_as_without(const PointCloud& plane, const FilterOptions& o, double far) {
  PointCloud with = plane;
  with.positions.insert(with.positions.begin() + 700, Eigen::Vector3d(far, -far, far));
  if (with.has_normals()) with.normals.insert(with.normals.begin() + 700, Eigen::Vector3f(0, 0, 1));
  const FilterResult a = robust_filter(plane, o);
  const FilterResult b = robust_filter(with, o);
  ASSERT_EQ(b.cloud.size(), a.cloud.size()) << "far point at " << far;
  EXPECT_GT(a.cloud.size(), plane.size() / 2);
  for (std::size_t k = 0; k < a.cloud.size(); ++k) {
    EXPECT_EQ(b.cloud.positions[k], a.cloud.positions[k]);
    const double s = attr(a.cloud, "source_index").values[k];
    EXPECT_EQ(attr(b.cloud, "source_index").values[k], s < 700 ? s : s + 1);
  }
  EXPECT_EQ(b.stats.h, a.stats.h);
  EXPECT_EQ(b.stats.unsupported, a.stats.unsupported + 1);
  // The far point is removed as unsupported, at its input position.
  bool found = false;
  for (std::size_t k = 0; k < b.outliers.size(); ++k)
    if (attr(b.outliers, "source_index").values[k] == 700) {
      found = true;
      EXPECT_EQ(attr(b.outliers, "flags").values[k], kFlagUnsupported);
      EXPECT_EQ(b.outliers.positions[k], with.positions[700]);
    }
  EXPECT_TRUE(found);
  for (const auto& p : b.cloud.positions) EXPECT_TRUE(p.allFinite());
}

TEST(InputGroupsTest, OneFarPointChangesNothingElse) {
  const PointCloud plane = test::noisy_plane(2000, 0.2, 0.001, 53);
  for (double far : {1e7, 1e25}) expect_same_as_without(plane, FilterOptions{}, far);
  FilterOptions fixed;
  fixed.scale = ScaleMode::kFixed;
  fixed.h = 0.02;
  expect_same_as_without(plane, fixed, 1e12);
}

TEST(InputGroupsTest, AFarClusterIsFilteredOnItsOwn) {
  // Two planes 10 km apart, the far one under 1 % of the points (outside the percentile box):
  // each is filtered with its own h.
  const PointCloud near = test::noisy_plane(5000, 0.2, 0.001, 54);
  PointCloud far = test::noisy_plane(40, 0.05, 0.0003, 55);
  for (auto& p : far.positions) p += Eigen::Vector3d(1e4, 0, 0);
  PointCloud both = near;
  append(both, far);
  const FilterResult r = robust_filter(both);
  const detail::FarSplit split = detail::split_far_points(both);
  EXPECT_EQ(split.far.size(), far.size());
  std::size_t out_far = 0;
  for (const auto& p : r.cloud.positions) out_far += p.x() > 5e3 ? 1 : 0;
  EXPECT_GT(out_far, far.size() / 2);  // the far plane survives as a surface of its own
  EXPECT_EQ(total_merge_count(r) + r.outliers.size(), both.size());
  const FilterResult alone = robust_filter(near);
  EXPECT_EQ(r.stats.h, alone.stats.h);
}

// A few points have no bulk: the percentiles of three points are single points, so the box held
// one of them and the other two, split again, fell outside their own box (no point inside) and
// were split for ever (a stack overflow: `scanclean filter` on a 3-point triangle crashed).
TEST(InputGroupsTest, AFewPointsWithoutABulkAreOneGroup) {
  PointCloud two;
  two.positions = {{1, 0, 0}, {0, 1, 0}};
  const detail::FarSplit split = detail::split_far_points(two);
  EXPECT_EQ(split.near.size(), 2u);
  EXPECT_TRUE(split.far.empty());
  for (std::size_t n : {2u, 3u, 4u, 5u, 7u}) {
    PointCloud c;
    for (std::size_t i = 0; i < n; ++i)
      c.positions.emplace_back(static_cast<double>(i % 2), static_cast<double>(i / 2 % 2),
                               static_cast<double>(i / 4));
    const FilterResult r = robust_filter(c);
    EXPECT_EQ(total_merge_count(r) + r.outliers.size(), n) << n << " points";
  }
}

}  // namespace
}  // namespace scanclean

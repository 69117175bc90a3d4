// The octant groups of one grid cell's queries (filter/src/cell_groups.h): every query in the
// group of its octant about the centre of their bounding box, each group's box the tightest
// around its members.

#include "../../filter/src/cell_groups.h"
#include "support/synthetic.h"

#include <gtest/gtest.h>

#include <array>
#include <random>

namespace scanclean::detail {
namespace {

TEST(CellGroupsTest, EachQueryGoesToItsOctantAndEachBoxIsTight) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  OctantGroups g;
  for (std::size_t n : {1u, 2u, 7u, 200u}) {
    std::vector<Eigen::Vector3f> p(n);
    for (auto& q : p) {
      const float z = 0.2f * u(rng), y = u(rng), x = u(rng);  // gcc's order (test::draw_point)
      q = Eigen::Vector3f(x, y, z);
    }
    group_by_octant(
        n, [&](std::size_t k) -> const Eigen::Vector3f& { return p[k]; }, g);
    Eigen::Vector3f lo = p[0], hi = p[0];
    for (const auto& q : p) {
      lo = lo.cwiseMin(q);
      hi = hi.cwiseMax(q);
    }
    const Eigen::Vector3f mid = 0.5f * (lo + hi);
    std::array<std::uint32_t, 8> members{};
    std::array<Eigen::Vector3f, 8> glo, ghi;
    ASSERT_EQ(g.octant.size(), n);
    for (std::size_t k = 0; k < n; ++k) {
      const int want = (p[k].x() >= mid.x() ? 1 : 0) | (p[k].y() >= mid.y() ? 2 : 0) |
                       (p[k].z() >= mid.z() ? 4 : 0);
      ASSERT_EQ(g.octant[k], want) << k;
      if (members[want]++ == 0) {
        glo[want] = ghi[want] = p[k];
      } else {
        glo[want] = glo[want].cwiseMin(p[k]);
        ghi[want] = ghi[want].cwiseMax(p[k]);
      }
    }
    EXPECT_EQ(g.members, members);
    for (int o = 0; o < 8; ++o) {
      if (members[o] == 0) continue;
      EXPECT_EQ(g.lo[o], glo[o]) << o;
      EXPECT_EQ(g.hi[o], ghi[o]) << o;
    }
  }
}

// A group's queries reused from a previous call do not leak into the next one.
TEST(CellGroupsTest, ReusedGroupsStartAfresh) {
  OctantGroups g;
  std::vector<Eigen::Vector3f> a = {{0, 0, 0}, {1, 1, 1}, {1, 0, 0}};
  group_by_octant(
      a.size(), [&](std::size_t k) -> const Eigen::Vector3f& { return a[k]; }, g);
  std::vector<Eigen::Vector3f> b = {{5, 5, 5}};
  group_by_octant(
      b.size(), [&](std::size_t k) -> const Eigen::Vector3f& { return b[k]; }, g);
  EXPECT_EQ(g.octant.size(), 1u);
  EXPECT_EQ(g.members[7], 1u);  // the one point is at the centre: upper half on every axis
  std::uint32_t total = 0;
  for (std::uint32_t m : g.members) total += m;
  EXPECT_EQ(total, 1u);
  EXPECT_EQ(g.lo[7], b[0]);
  EXPECT_EQ(g.hi[7], b[0]);
}

}  // namespace
}  // namespace scanclean::detail

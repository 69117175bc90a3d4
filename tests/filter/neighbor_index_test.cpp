#include "../../filter/src/neighbor_index.h"
#include "support/synthetic.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

namespace scanclean {
namespace {

// A mix of a dense cluster, a sheet and sparse far points, so that both the grid path and the
// k-d tree path are exercised.
std::vector<Eigen::Vector3f> mixed_points(std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> g(0.0f, 0.05f);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::vector<Eigen::Vector3f> p;
  // Several draws in one argument list, written out last to first: gcc's order
  // (test::draw_point).
  for (int i = 0; i < 2000; ++i) p.push_back(test::draw_point(rng, g, g, g).cast<float>());
  for (int i = 0; i < 2000; ++i) {
    const float z = 0.3f + 0.01f * g(rng), y = u(rng), x = u(rng);
    p.emplace_back(x, y, z);
  }
  for (int i = 0; i < 200; ++i) p.push_back(5.0f * test::draw_point(rng, u, u, u).cast<float>());
  p.push_back(p[10]);  // an exact duplicate
  return p;
}

TEST(NeighborIndexTest, RadiusQueriesMatchBruteForce) {
  const auto pts = mixed_points(7);  // seed 7: fixed fixture
  NeighborIndex index(pts, 0.05);
  std::mt19937 rng(11);  // seed 11: query choice
  std::uniform_int_distribution<std::size_t> pick(0, pts.size() - 1);
  for (float r : {0.01f, 0.05f, 0.12f, 0.5f, 3.0f}) {
    for (int k = 0; k < 60; ++k) {
      const Eigen::Vector3f q = pts[pick(rng)] + Eigen::Vector3f(0.003f, -0.002f, 0.001f);
      std::vector<std::uint32_t> got, want, slots;
      index.for_each_within(q, r, [&](std::uint32_t i, float d2) {
        got.push_back(i);
        EXPECT_NEAR(d2, (pts[i] - q).squaredNorm(), 1e-5f);
      });
      index.for_each_slot_within(q, r, [&](std::uint32_t s, float) {
        slots.push_back(index.order()[s]);
        EXPECT_EQ(index.slot_point(s), pts[index.order()[s]]);
      });
      for (std::uint32_t i = 0; i < pts.size(); ++i)
        if ((pts[i] - q).squaredNorm() < r * r) want.push_back(i);
      std::sort(got.begin(), got.end());
      std::sort(slots.begin(), slots.end());
      EXPECT_EQ(got, want) << "r = " << r;
      EXPECT_EQ(slots, want) << "r = " << r;
    }
  }
}

TEST(NeighborIndexTest, OrderIsAPermutation) {
  const auto pts = mixed_points(3);  // seed 3: fixed fixture
  NeighborIndex index(pts, 0.1);
  std::vector<std::uint32_t> o = index.order();
  std::sort(o.begin(), o.end());
  for (std::uint32_t i = 0; i < o.size(); ++i) ASSERT_EQ(o[i], i);
  for (std::uint32_t i = 0; i < pts.size(); ++i) EXPECT_EQ(index.order()[index.slot_of(i)], i);
}

TEST(NeighborIndexTest, CellsAreContiguousWithTheirPointsInIndexOrder) {
  // Fine cells over a wide extent: Morton codes of 42 bits (four passes of the radix sort) as
  // well as the usual few. Each cell's points are one run of slots, in increasing index order
  // (the sort is stable), and radius queries, which scan whole cells, match brute force.
  std::mt19937 rng(13);  // seed 13
  std::uniform_real_distribution<float> u(-5.0f, 5.0f);
  std::vector<Eigen::Vector3f> pts;
  for (int i = 0; i < 6000; ++i) {
    const float z = 0.001f * u(rng), y = u(rng), x = u(rng);  // gcc's order (test::draw_point)
    pts.emplace_back(x, y, z);
  }
  for (int i = 0; i < 300; ++i) pts.push_back(pts[static_cast<std::size_t>(i) * 7]);  // duplicates
  for (double cell : {0.001, 0.3}) {
    NeighborIndex index(pts, cell);
    ASSERT_GT(index.cell_count(), 0u);
    for (std::size_t c = 0; c < index.cell_count(); ++c)
      for (std::uint32_t s = index.cell_begin(c) + 1; s < index.cell_begin(c + 1); ++s)
        EXPECT_LT(index.order()[s - 1], index.order()[s]) << "cell " << c;
    for (int k = 0; k < 40; ++k) {
      const Eigen::Vector3f q = pts[static_cast<std::size_t>(k) * 7];
      const float r = static_cast<float>(cell) * 0.9f;
      std::vector<std::uint32_t> got, want;
      index.for_each_within(q, r, [&](std::uint32_t i, float) { got.push_back(i); });
      for (std::uint32_t i = 0; i < pts.size(); ++i)
        if ((pts[i] - q).squaredNorm() < r * r) want.push_back(i);
      std::sort(got.begin(), got.end());
      EXPECT_EQ(got, want) << "cell " << cell << " query " << k;
      EXPECT_GE(want.size(), 2u);  // itself and its duplicate at least
    }
  }
}

TEST(NeighborIndexTest, KnnMatchesBruteForce) {
  const auto pts = mixed_points(5);  // seed 5: fixed fixture
  for (double cell : {0.0, 0.05}) {
    NeighborIndex index(pts, cell);
    std::vector<std::pair<float, std::uint32_t>> got;
    for (std::size_t qi = 0; qi < pts.size(); qi += 97) {
      const Eigen::Vector3f q = pts[qi];
      index.knn(q, 20, got);
      std::vector<float> want;
      for (const auto& p : pts) want.push_back((p - q).squaredNorm());
      std::sort(want.begin(), want.end());
      ASSERT_EQ(got.size(), 20u);
      for (std::size_t k = 0; k < 20; ++k) EXPECT_NEAR(got[k].first, want[k], 1e-6f);
      EXPECT_FLOAT_EQ((pts[got[19].second] - q).squaredNorm(), got[19].first);
    }
  }
}

// rough_kth_distance against its definition, by brute force (the oracle): the median over the
// sampled points of the distance to the ks-th nearest among every step-th point. The larger
// cloud's subsample is searched as two trees (at 8,192 subsampled points and more), the smaller
// one's as one.
TEST(NeighborIndexTest, RoughKthDistanceMatchesBruteForce) {
  std::mt19937 rng(71);  // seed 71
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::normal_distribution<float> g(0.0f, 0.01f);
  for (const std::size_t n : {std::size_t{30000}, std::size_t{200000}}) {
    std::vector<Eigen::Vector3f> p(n);
    for (auto& x : p) x = test::draw_point(rng, u, u, g).cast<float>();
    const std::size_t kk = 9, samples = 301;
    const std::size_t step = std::clamp<std::size_t>(n / (8 * kk), 1, 16);
    const std::size_t ks = std::max<std::size_t>(2, (kk + step / 2) / step);
    std::vector<double> est(samples);
    for (std::size_t k = 0; k < samples; ++k) {
      const Eigen::Vector3f& q = p[k * n / samples];
      std::vector<float> d2;
      for (std::size_t i = 0; i < n; i += step) d2.push_back((p[i] - q).squaredNorm());
      std::nth_element(d2.begin(), d2.begin() + static_cast<std::ptrdiff_t>(ks - 1), d2.end());
      est[k] = std::sqrt(static_cast<double>(d2[ks - 1]));
    }
    std::nth_element(est.begin(), est.begin() + (samples - 1) / 2, est.end());
    const double want = est[(samples - 1) / 2];
    EXPECT_NEAR(rough_kth_distance(p, kk, samples), want, 1e-6 * want) << n << " points";
  }
}

TEST(NeighborIndexTest, EmptyAndTinySets) {
  NeighborIndex empty({}, 1.0);
  int calls = 0;
  empty.for_each_within(Eigen::Vector3f::Zero(), 1.0f, [&](std::uint32_t, float) { ++calls; });
  EXPECT_EQ(calls, 0);
  NeighborIndex one({Eigen::Vector3f(1, 2, 3)}, 0.5);
  std::vector<std::pair<float, std::uint32_t>> nn;
  one.knn(Eigen::Vector3f(1, 2, 3), 5, nn);
  ASSERT_EQ(nn.size(), 1u);
  EXPECT_EQ(nn[0].first, 0.0f);
  one.for_each_within(Eigen::Vector3f(100, 2, 3), 1.0f, [&](std::uint32_t, float) { ++calls; });
  EXPECT_EQ(calls, 0);
}

// The per-point rank of per-cell values against the sorted array of every point's value (the
// oracle), and the adjacent counts against the distance bound they promise.
TEST(NeighborIndexTest, AdjacentCountsAndTheirRanksOverThePoints) {
  std::mt19937 rng(23);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<Eigen::Vector3f> p;
  for (int k = 0; k < 4000; ++k) {
    const float z = 0.1f * u(rng), y = u(rng) * u(rng), x = u(rng);  // gcc's order
    p.emplace_back(x, y, z);
  }
  const NeighborIndex index(p, 0.05);
  const std::vector<std::uint32_t> counts = index.adjacent_counts();
  ASSERT_EQ(counts.size(), index.cell_count());
  std::vector<std::uint32_t> per_point;
  for (std::size_t c = 0; c < counts.size(); ++c) {
    for (std::uint32_t s = index.cell_begin(c); s < index.cell_begin(c + 1); ++s) {
      per_point.push_back(counts[c]);
      std::uint32_t within = 0;
      index.for_each_slot_within(index.slot_point(s), index.max_adjacent_radius(),
                                 [&](std::uint32_t, float) { ++within; });
      EXPECT_LE(within, counts[c]) << "slot " << s;
    }
  }
  std::sort(per_point.begin(), per_point.end());
  for (const std::size_t rank : {std::size_t{0}, per_point.size() / 4, (per_point.size() - 1) / 2,
                                 per_point.size() / 2, per_point.size() - 1})
    EXPECT_EQ(index.value_at_point_rank(counts, rank), per_point[rank]) << "rank " << rank;
}

TEST(NeighborIndexTest, CellOctantsSplitTheCellsInEightBoxes) {
  // Every point lies in its octant's box (up to the 1e-4 cells the box is grown by, which
  // covers rounding here), the octant's bits say which half of the cell it is in along each
  // axis, and the box is half a cell wide (plus the growth) and the same for every point of the
  // octant.
  const std::vector<Eigen::Vector3f> pts = mixed_points(21);
  const double cell = 0.07;
  NeighborIndex index(pts, cell);
  std::vector<std::pair<std::pair<std::int64_t, int>, Eigen::Vector3f>> seen;
  std::size_t inside = 0, checked = 0;
  for (std::size_t s = 0; s < index.size(); ++s) {
    const Eigen::Vector3f& q = index.slot_point(s);
    const std::int64_t c = index.adjacent_cell(q, 0.5f * static_cast<float>(cell));
    if (c < 0) continue;
    ++checked;
    Eigen::Vector3f lo, hi;
    const int octant = index.cell_octant(q, lo, hi);
    ASSERT_GE(octant, 0);
    ASSERT_LT(octant, 8);
    inside += (q.array() >= lo.array()).all() && (q.array() <= hi.array()).all() ? 1 : 0;
    for (int a = 0; a < 3; ++a)
      EXPECT_NEAR(hi[a] - lo[a], 0.5 * cell * (1 + 4e-4), 1e-5) << "slot " << s;
    // The same box for every point of the same cell and octant.
    bool found = false;
    for (const auto& [k, box_lo] : seen)
      if (k.first == c && k.second == octant) {
        EXPECT_EQ(box_lo, lo) << "slot " << s;
        found = true;
      }
    if (!found && seen.size() < 4000) seen.push_back({{c, octant}, lo});
    // Points in opposite halves of a cell along an axis have that bit different.
    const Eigen::Vector3f mid_lo = lo - Eigen::Vector3f::Constant(1e-4f * static_cast<float>(cell));
    for (int a = 0; a < 3; ++a) {
      const bool upper = (octant >> a) & 1;
      const float cell_lo = upper ? mid_lo[a] - 0.5f * static_cast<float>(cell) : mid_lo[a];
      EXPECT_GE(q[a], cell_lo - 1e-5f) << "slot " << s;
      EXPECT_LE(q[a], cell_lo + static_cast<float>(cell) + 1e-5f) << "slot " << s;
    }
  }
  EXPECT_EQ(inside, checked);
  EXPECT_GT(checked, index.size() * 9 / 10);
}

}  // namespace
}  // namespace scanclean

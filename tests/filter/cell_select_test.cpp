// The cached cell-neighbourhood radius queries (filter/src/cell_select.h) against the index's own
// for_each_slot_within (the oracle): the same slots in the same order, on the fast path, on the
// fallback (a radius larger than the grid answers), across several indexes sharing one thread's
// cache, for a query off the grid, and through the parts of the cached neighbourhoods.

#include "../../filter/src/cell_select.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace scanclean::detail {
namespace {

std::vector<Eigen::Vector3f> surface_points(int n, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::normal_distribution<float> g(0.0f, 0.01f);
  std::vector<Eigen::Vector3f> p;
  for (int i = 0; i < n; ++i) {
    const float x = u(rng), y = u(rng);
    p.emplace_back(x, y, 0.2f * x * y + g(rng));  // a noisy saddle
  }
  return p;
}

std::vector<std::uint32_t> oracle(const NeighborIndex& index, const Eigen::Vector3f& q, float r) {
  std::vector<std::uint32_t> out;
  index.for_each_slot_within(q, r, [&](std::uint32_t s, float) { out.push_back(s); });
  return out;
}

// The slots of `slots` (in their order) that lie within scale sigma[t] + margin of q, in the
// selections' float rounding: the oracle of select_within_reach on top of the radius query.
std::vector<std::uint32_t> within_reach(const NeighborIndex& index, const Eigen::Vector3f& q,
                                        const std::vector<std::uint32_t>& slots,
                                        const std::vector<float>& sigma, float scale,
                                        float margin) {
  std::vector<std::uint32_t> out;
  for (const std::uint32_t t : slots) {
    const Eigen::Vector3f d = index.slot_point(t) - q;
    const float dx = d.x(), dy = d.y(), dz = d.z(), d2 = dx * dx + dy * dy + dz * dz;
    const float reach = scale * sigma[t] + margin;
    if (d2 < reach * reach) out.push_back(t);
  }
  return out;
}

TEST(CellSelectTest, SameSlotsInTheSameOrderAsTheIndex) {
  const std::vector<Eigen::Vector3f> pts = surface_points(20000, 3);
  const float cell = 0.05f;
  NeighborIndex a(pts, cell), b(surface_points(5000, 4), 2 * cell);
  const std::uint64_t key_a = new_cell_cache_key(), key_b = new_cell_cache_key();
  ASSERT_NE(key_a, key_b);
  CellSelect sel;
  std::size_t fast = 0, total = 0;
  for (std::size_t s = 0; s < a.size(); s += 37) {
    const Eigen::Vector3f q = a.slot_point(s);
    // Radii within the grid's fast path and beyond it (fallback), alternating indexes so that
    // the cache holds cells of both.
    for (const float r : {0.3f * cell, 0.9f * cell, 2.5f * cell}) {
      std::vector<std::uint32_t> got;
      sel.for_each_slot_within(a, key_a, q, r, [&](std::uint32_t t) { got.push_back(t); });
      EXPECT_EQ(got, oracle(a, q, r)) << "slot " << s << " r " << r;
      fast += sel.select(a, key_a, q, r) != CellSelect::kNotGrid ? 1 : 0;
      ++total;
      got.clear();
      sel.for_each_slot_within(b, key_b, q, r, [&](std::uint32_t t) { got.push_back(t); });
      EXPECT_EQ(got, oracle(b, q, r)) << "slot " << s << " r " << r << " (second index)";
    }
  }
  EXPECT_GT(fast, total / 2);  // the cache answered most queries
  EXPECT_LT(fast, total);      // and the fallback was exercised
}

TEST(CellSelectTest, QueriesOffTheGridAndEmptyRadii) {
  NeighborIndex a(surface_points(2000, 5), 0.1);
  const std::uint64_t key = new_cell_cache_key();
  CellSelect sel;
  const Eigen::Vector3f far(5.0f, 5.0f, 5.0f);
  EXPECT_EQ(sel.select(a, key, far, 0.05f), CellSelect::kNotGrid);
  std::vector<std::uint32_t> got;
  sel.for_each_slot_within(a, key, far, 0.05f, [&](std::uint32_t t) { got.push_back(t); });
  EXPECT_TRUE(got.empty());
  const Eigen::Vector3f q = a.slot_point(10);
  EXPECT_EQ(sel.select(a, key, q, 0.0f), 0u);
  EXPECT_EQ(sel.select(a, key, q, -0.05f), 0u);
  EXPECT_EQ(oracle(a, q, -0.05f).size(), 0u);
  EXPECT_GT(sel.select(a, key, q, 0.05f), 0u);
}

TEST(CellSelectTest, WithinReachKeepsTheSlotsWithinBothRadii) {
  // The oracle: the index's own radius query, filtered by the reach in the same float rounding.
  const std::vector<Eigen::Vector3f> pts = surface_points(20000, 8);
  const float cell = 0.05f, scale = 3.03f, margin = 0.004f;
  NeighborIndex a(pts, cell);
  std::vector<float> sigma(a.size());
  for (std::size_t t = 0; t < a.size(); ++t) sigma[t] = 0.003f + 0.01f * static_cast<float>(t % 7);
  const std::uint64_t key = new_cell_cache_key();
  CellSelect sel;
  for (std::size_t s = 0; s < a.size(); s += 53) {
    const Eigen::Vector3f q = a.slot_point(s);
    for (const float r : {0.5f * cell, 0.95f * cell}) {
      const std::vector<std::uint32_t> want =
          within_reach(a, q, oracle(a, q, r), sigma, scale, margin);
      const std::size_t n = sel.select_within_reach(
          a, key, q, r, [&](std::uint32_t t) { return sigma[t]; }, scale, margin);
      ASSERT_NE(n, CellSelect::kNotGrid);
      EXPECT_EQ(std::vector<std::uint32_t>(sel.hits(), sel.hits() + n), want) << "slot " << s;
      // A plain select on the same cached cells afterwards: the full radius query.
      const std::size_t m = sel.select(a, key, q, r);
      EXPECT_EQ(m, oracle(a, q, r).size());
    }
  }
}

TEST(CellSelectTest, PartsGiveTheSlotsOfTheWholeNeighbourhood) {
  // Many queries per cell, as the filter makes them: consecutive points of the grid order, at
  // their own positions and at positions on the octants' boundaries (halves of a cell, where
  // rounding may put a query just outside its octant's box), with radii that grow and shrink
  // (parts made again for a larger radius), plain and within-reach selections on the same key
  // (parts made again with sigma). Oracle: the index's own query; and the same selection
  // without parts.
  const std::vector<Eigen::Vector3f> pts = surface_points(20000, 12);
  const float cell = 0.05f, scale = 3.03f, margin = 0.004f;
  NeighborIndex a(pts, cell);
  std::vector<float> sigma(a.size());
  for (std::size_t t = 0; t < a.size(); ++t) sigma[t] = 0.002f + 0.004f * static_cast<float>(t % 5);
  const std::uint64_t key = new_cell_cache_key();
  CellSelect sel, whole;
  std::mt19937 rng(12);  // seed 12
  std::uniform_real_distribution<float> radius(0.2f * cell, 0.99f * cell);
  std::size_t queries = 0;
  for (std::size_t s = 0; s < a.size(); s += 3) {
    Eigen::Vector3f q = a.slot_point(s);
    if (s % 7 == 0)  // onto the boundary between two octants along x
      q.x() = (std::floor(q.x() / (0.5f * cell)) + 1.0f) * 0.5f * cell;
    const float r = radius(rng);
    const std::vector<std::uint32_t> want = oracle(a, q, r);
    const std::size_t n = sel.select(a, key, q, r);
    if (n == CellSelect::kNotGrid) continue;
    ++queries;
    ASSERT_EQ(std::vector<std::uint32_t>(sel.hits(), sel.hits() + n), want) << "slot " << s;
    const std::size_t m = whole.select(a, key, q, r, false);
    ASSERT_EQ(m, n);
    if (s % 2 == 0) {
      const std::vector<std::uint32_t> reach_want = within_reach(a, q, want, sigma, scale, margin);
      const std::size_t k = sel.select_within_reach(
          a, key, q, r, [&](std::uint32_t t) { return sigma[t]; }, scale, margin);
      ASSERT_EQ(std::vector<std::uint32_t>(sel.hits(), sel.hits() + k), reach_want) << "slot " << s;
    }
  }
  EXPECT_GT(queries, a.size() / 4);  // the grid answered most of them
}

TEST(CellSelectTest, CrowdedNeighbourhoodsAreLeftToTheIndex) {
  // 70,000 points in one cell: more than a cache entry holds.
  std::vector<Eigen::Vector3f> pts = surface_points(70000, 6);
  for (auto& p : pts) p *= 0.01f;
  NeighborIndex a(pts, 0.5);
  const std::uint64_t key = new_cell_cache_key();
  CellSelect sel;
  const Eigen::Vector3f q = a.slot_point(123);
  EXPECT_EQ(sel.select(a, key, q, 0.004f), CellSelect::kNotGrid);
  std::vector<std::uint32_t> got;
  sel.for_each_slot_within(a, key, q, 0.004f, [&](std::uint32_t t) { got.push_back(t); });
  EXPECT_EQ(got, oracle(a, q, 0.004f));
  EXPECT_GT(got.size(), 100u);
}

}  // namespace
}  // namespace scanclean::detail

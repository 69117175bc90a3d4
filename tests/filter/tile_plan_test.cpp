// The tile plan (filter/src/tile_plan.h) against brute-force counts over the histogram: every
// occupied cell in exactly one tile, the counts of each tile with and without its halo, tiles
// within the limit, the processes' loads balanced, and the halo lookup against a test of every
// tile.
#include "../../filter/src/tile_plan.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <numeric>
#include <random>
#include <vector>

namespace scanclean::detail {
namespace {

// Points in the cells of `b` grown by `grow` cells (clipped to the grid), counted cell by cell.
std::uint64_t brute_count(const TileGrid& g, const std::vector<std::uint64_t>& hist,
                          const CellBox& b, std::int64_t grow) {
  std::uint64_t n = 0;
  for (std::int64_t z = std::max<std::int64_t>(0, b[2] - grow);
       z < std::min(g.dims[2], b[5] + grow); ++z)
    for (std::int64_t y = std::max<std::int64_t>(0, b[1] - grow);
         y < std::min(g.dims[1], b[4] + grow); ++y)
      for (std::int64_t x = std::max<std::int64_t>(0, b[0] - grow);
           x < std::min(g.dims[0], b[3] + grow); ++x)
        n += hist[g.flat({x, y, z})];
  return n;
}

// A grid of 40 x 30 x 6 cells of 0.5 m whose occupancy is a noisy floor (z = 0 and 1) with two
// dense blocks and empty cells between: what a scan's histogram looks like.
struct Scene {
  TileGrid grid;
  std::vector<std::uint64_t> hist;
  std::uint64_t total = 0;
};

Scene scene(std::uint32_t seed) {
  Scene s;
  s.grid.lo = Eigen::Vector3d(-3.0, 2.0, 0.5);
  s.grid.cell = 0.5;
  s.grid.dims = {40, 30, 6};
  s.hist.assign(s.grid.cells(), 0);
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> floor_count(0, 400), block_count(300, 900);
  std::bernoulli_distribution hole(0.1);
  for (std::int64_t y = 0; y < 30; ++y)
    for (std::int64_t x = 0; x < 40; ++x) {
      for (std::int64_t z = 0; z < 2; ++z)
        if (!hole(rng))
          s.hist[s.grid.flat({x, y, z})] = static_cast<std::uint64_t>(floor_count(rng));
      if ((x >= 5 && x < 9 && y >= 3 && y < 8) || (x >= 30 && x < 33 && y >= 20 && y < 26))
        for (std::int64_t z = 2; z < 6; ++z)
          s.hist[s.grid.flat({x, y, z})] = static_cast<std::uint64_t>(block_count(rng));
    }
  s.total = std::accumulate(s.hist.begin(), s.hist.end(), std::uint64_t{0});
  return s;
}

TEST(TilePlan, TheOccupancyGridCoversTheBoxWithAboutTwoMillionCells) {
  struct Case {
    Eigen::Vector3d lo, hi;
  };
  const Case cases[] = {
      {{-1, -2, -3}, {4, 5, 6}},              // a room
      {{0, 0, 0}, {1000, 800, 0}},            // flat (an aerial scan's ground)
      {{10, 10, 10}, {10.001, 500, 10.001}},  // a long thin strip
  };
  for (const Case& c : cases) {
    const Eigen::AlignedBox3d box(c.lo, c.hi);
    const TileGrid g = occupancy_grid(box);
    EXPECT_EQ(g.lo, box.min());
    for (int a = 0; a < 3; ++a) {
      EXPECT_GE(g.dims[a], 1);
      EXPECT_LE(g.dims[a], 257) << "axis " << a;  // 256, or one more by rounding
      EXPECT_GE(static_cast<double>(g.dims[a]) * g.cell, box.diagonal()[a] * (1 - 1e-12))
          << "axis " << a;
    }
    EXPECT_LE(g.cells(), std::size_t{2000000} + 3 * 256 * 256);
    // Corners and the centre fall into cells of the grid (clamped at the upper faces).
    for (const Eigen::Vector3d& p :
         {Eigen::Vector3d(box.min()), Eigen::Vector3d(box.max()), Eigen::Vector3d(box.center())}) {
      const auto cell = g.cell_of(p);
      for (int a = 0; a < 3; ++a) {
        EXPECT_GE(cell[a], 0);
        EXPECT_LT(cell[a], g.dims[a]);
      }
    }
  }
  // A box of one location: one cell.
  const TileGrid one =
      occupancy_grid(Eigen::AlignedBox3d(Eigen::Vector3d(1, 2, 3), Eigen::Vector3d(1, 2, 3)));
  EXPECT_EQ(one.cells(), 1u);
}

TEST(TilePlan, EveryOccupiedCellIsInExactlyOneTileWithinTheLimit) {
  const Scene s = scene(5);
  const double halo = 0.6;  // 2 cells of 0.5 m
  const std::uint64_t limit = s.total / 6;
  const TilePlan plan = plan_tiles(s.grid, s.hist, halo, limit, 3);
  EXPECT_EQ(plan.halo_cells, 2);
  ASSERT_GT(plan.tiles.size(), 6u);
  ASSERT_EQ(plan.cells.size(), plan.tiles.size());
  // Each cell: the tiles whose cells hold it.
  std::vector<int> covered(s.grid.cells(), 0);
  std::uint64_t own_sum = 0;
  for (std::size_t t = 0; t < plan.tiles.size(); ++t) {
    const CellBox& b = plan.cells[t];
    const TilePlanEntry& e = plan.tiles[t];
    for (std::int64_t z = b[2]; z < b[5]; ++z)
      for (std::int64_t y = b[1]; y < b[4]; ++y)
        for (std::int64_t x = b[0]; x < b[3]; ++x) {
          ++covered[s.grid.flat({x, y, z})];
          EXPECT_EQ(plan.tile_of_cell[s.grid.flat({x, y, z})], t);
        }
    EXPECT_EQ(e.own_points, brute_count(s.grid, s.hist, b, 0)) << "tile " << t;
    EXPECT_GT(e.own_points, 0u) << "tile " << t;
    EXPECT_EQ(e.with_halo, brute_count(s.grid, s.hist, b, plan.halo_cells)) << "tile " << t;
    EXPECT_LE(e.with_halo, limit) << "tile " << t;
    // The box is the cells' box in metres.
    for (int a = 0; a < 3; ++a) {
      EXPECT_DOUBLE_EQ(e.box.min()[a], s.grid.lo[a] + s.grid.cell * static_cast<double>(b[a]));
      EXPECT_DOUBLE_EQ(e.box.max()[a], s.grid.lo[a] + s.grid.cell * static_cast<double>(b[a + 3]));
    }
    own_sum += e.own_points;
  }
  EXPECT_EQ(own_sum, s.total);
  for (std::size_t c = 0; c < covered.size(); ++c) {
    EXPECT_LE(covered[c], 1) << "cell " << c;
    if (s.hist[c] > 0) {
      EXPECT_EQ(covered[c], 1) << "occupied cell " << c;
    }
  }
  // A point's home tile is the tile of its cell.
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> ux(-3.0, 17.0), uy(2.0, 17.0), uz(0.5, 3.5);
  for (int k = 0; k < 1000; ++k) {
    const Eigen::Vector3d p(ux(rng), uy(rng), uz(rng));
    EXPECT_EQ(plan.tile_of(p), plan.tile_of_cell[s.grid.flat(s.grid.cell_of(p))]);
  }
}

TEST(TilePlan, ProcessesGetTheLargestTilesFirstEachToTheLeastLoaded) {
  const Scene s = scene(6);
  for (const int ranks : {1, 2, 3, 5}) {
    const TilePlan plan = plan_tiles(s.grid, s.hist, 0.6, s.total / 8, ranks);
    std::vector<std::uint64_t> load(static_cast<std::size_t>(ranks), 0);
    std::uint64_t largest = 0;
    for (const TilePlanEntry& e : plan.tiles) {
      ASSERT_GE(e.rank, 0);
      ASSERT_LT(e.rank, ranks);
      load[static_cast<std::size_t>(e.rank)] += e.with_halo;
      largest = std::max(largest, e.with_halo);
    }
    // Greedy by decreasing size: no process ends more than one tile above the least loaded.
    const auto [lo, hi] = std::minmax_element(load.begin(), load.end());
    EXPECT_LE(*hi - *lo, largest) << ranks << " ranks";
    if (static_cast<std::size_t>(ranks) <= plan.tiles.size()) {
      EXPECT_GT(*lo, 0u);
    }
    // The same plan, whatever the number of processes, apart from the ranks.
    const TilePlan one = plan_tiles(s.grid, s.hist, 0.6, s.total / 8, 1);
    ASSERT_EQ(one.cells, plan.cells);
  }
}

// The order in which processes take tiles as they become free (TileComm::take): every tile
// once, by decreasing points with the halo, ties in tile order; the first `ranks` of it are
// the tiles the plan deals first, one to each process.
TEST(TilePlan, TilesAreTakenLargestFirstTiesInTileOrder) {
  const Scene s = scene(7);
  const TilePlan plan = plan_tiles(s.grid, s.hist, 0.6, s.total / 12, 3);
  const std::vector<std::size_t> order = largest_first(plan);
  ASSERT_EQ(order.size(), plan.tiles.size());
  ASSERT_GE(order.size(), 4u);
  std::vector<std::size_t> sorted = order;
  std::sort(sorted.begin(), sorted.end());
  for (std::size_t k = 0; k < sorted.size(); ++k) ASSERT_EQ(sorted[k], k) << "not every tile once";
  for (std::size_t j = 1; j < order.size(); ++j) {
    const std::uint64_t a = plan.tiles[order[j - 1]].with_halo, b = plan.tiles[order[j]].with_halo;
    EXPECT_GE(a, b) << "position " << j;
    if (a == b) {
      EXPECT_LT(order[j - 1], order[j]) << "a tie out of tile order at " << j;
    }
  }
  std::vector<int> first_ranks;
  for (std::size_t j = 0; j < 3; ++j) first_ranks.push_back(plan.tiles[order[j]].rank);
  std::sort(first_ranks.begin(), first_ranks.end());
  EXPECT_EQ(first_ranks, (std::vector<int>{0, 1, 2}));
}

TEST(TilePlan, ALimitAboveTheCloudGivesOneTileAndAHaloLargerThanTheCloudNoCut) {
  const Scene s = scene(7);
  const TilePlan whole = plan_tiles(s.grid, s.hist, 0.6, s.total, 4);
  ASSERT_EQ(whole.tiles.size(), 1u);
  EXPECT_EQ(whole.tiles[0].own_points, s.total);
  EXPECT_EQ(whole.tiles[0].rank, 0);
  // A halo wider than the grid: every half holds the whole cloud, no cut helps, one tile stays.
  const TilePlan halo = plan_tiles(s.grid, s.hist, 100.0, s.total / 4, 2);
  ASSERT_EQ(halo.tiles.size(), 1u);
  EXPECT_EQ(halo.tiles[0].with_halo, s.total);
  // An empty histogram: no tile.
  EXPECT_TRUE(
      plan_tiles(s.grid, std::vector<std::uint64_t>(s.grid.cells(), 0), 0.6, 100, 1).tiles.empty());
}

TEST(TilePlan, TheHaloLookupFindsEveryTileWhoseGrownBoxHoldsAPoint) {
  const Scene s = scene(8);
  const Eigen::AlignedBox3d box(s.grid.lo, s.grid.lo + s.grid.cell * Eigen::Vector3d(40, 30, 6));
  for (const double halo : {0.3, 1.0, 2.6}) {
    const TilePlan plan = plan_tiles(s.grid, s.hist, halo, s.total / 10, 2);
    ASSERT_GT(plan.tiles.size(), 4u);
    const HaloLookup lookup(plan, box, halo);
    std::mt19937 rng(21);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::vector<std::uint32_t> hits;
    std::size_t in_several = 0;
    for (int k = 0; k < 4000; ++k) {
      const Eigen::Vector3d p =
          box.min() + (box.diagonal().array() * Eigen::Array3d(u(rng), u(rng), u(rng))).matrix();
      lookup.tiles_of(p, hits);
      std::vector<std::uint32_t> expected{plan.tile_of(p)};
      for (std::uint32_t t = 0; t < plan.tiles.size(); ++t) {
        if (t == expected[0]) continue;
        const Eigen::AlignedBox3d& b = plan.tiles[t].box;
        bool within = true;
        for (int a = 0; a < 3; ++a)
          within = within && p[a] >= b.min()[a] - halo && p[a] <= b.max()[a] + halo;
        if (within) expected.push_back(t);
      }
      ASSERT_EQ(hits, expected) << "point " << p.transpose() << ", halo " << halo;
      in_several += hits.size() > 1 ? 1 : 0;
    }
    EXPECT_GT(in_several, 0u) << "no point in a halo: the test shows nothing";
  }
}

}  // namespace
}  // namespace scanclean::detail

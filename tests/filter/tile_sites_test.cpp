// The kernel sites of a tiled run (filter/src/tile_sites.h) against the in-memory run's order:
// the site grid sorts points as the point index does, and the sites marked from the counting
// pass are every stride-th point of that order, for one process or several.
#include "../../filter/src/tile_sites.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <numeric>
#include <random>
#include <set>
#include <vector>

#include "../../filter/src/neighbor_index.h"
#include "../../filter/src/parallel.h"
#include "../../filter/src/tile_exchange.h"
#include "tiled_test_support.h"

namespace scanclean::detail {
namespace {

// Clumps of points around random centres in a 40 m x 30 m x 5 m region 1 km from the origin
// (float coordinates relative to the box centre then round as a survey's do), and a few
// coincident copies.
PointCloud clumps(std::size_t n, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> ux(1000.0, 1040.0), uy(-515.0, -485.0), uz(0.0, 5.0);
  std::normal_distribution<double> spread(0.0, 0.4);
  PointCloud c;
  while (c.size() < n) {
    const Eigen::Vector3d centre(ux(rng), uy(rng), uz(rng));
    for (int k = 0; k < 200 && c.size() < n; ++k)
      c.positions.push_back(centre + Eigen::Vector3d(spread(rng), spread(rng), spread(rng)));
  }
  for (std::size_t k = 0; k < 50; ++k) c.positions[k + 100] = c.positions[k];
  return c;
}

// The in-memory run's order: its point index over the float points relative to the box centre.
std::vector<std::uint32_t> index_order(const PointCloud& c, double cell) {
  const Eigen::Vector3d origin = bounding_box_of(c.positions).center();
  std::vector<Eigen::Vector3f> pf;
  for (const auto& p : c.positions) pf.push_back((p - origin).cast<float>());
  const NeighborIndex index(pf, cell);
  return index.order();
}

TEST(TileSites, TheSiteGridOrdersPointsAsThePointIndexDoes) {
  const PointCloud c = clumps(30000, 3);
  const Eigen::AlignedBox3d box = bounding_box_of(c.positions);
  const Eigen::Vector3d origin = box.center();
  // Cells of about a clump, of a point spacing, and so small that the index caps its cell count.
  for (const double cell : {0.9, 0.05, 1e-6}) {
    const SiteGrid g = site_grid(box, origin, cell);
    std::vector<std::uint32_t> order(c.size());
    std::iota(order.begin(), order.end(), 0u);
    std::vector<std::uint64_t> code(c.size());
    for (std::size_t i = 0; i < c.size(); ++i)
      code[i] = g.code((c.positions[i] - origin).cast<float>());
    std::stable_sort(order.begin(), order.end(),
                     [&](std::uint32_t a, std::uint32_t b) { return code[a] < code[b]; });
    EXPECT_EQ(order, index_order(c, cell)) << "cell " << cell;
  }
}

// The records the processes mark as kernel sites (each reading its own range, in chunks).
std::set<std::uint64_t> marked_sites(const PointCloud& c, double cell, std::uint64_t stride,
                                     int ranks) {
  const TiledSource src = test::source_of(c);
  const Eigen::AlignedBox3d box = bounding_box_of(c.positions);
  const std::vector<std::vector<std::uint64_t>> per_rank =
      test::run_ranks<std::vector<std::uint64_t>>(ranks, [&](const TileComm& comm) {
        const auto range = record_range(src.records, comm);
        KernelSites sites(src, range, 777, comm, box, cell, stride);
        std::vector<std::uint64_t> mine;
        stream_records(src, range[0], range[1], 777,
                       [&](const PointCloud& part, const std::vector<std::uint64_t>& rec) {
                         for (std::size_t i = 0; i < part.size(); ++i)
                           if (sites.next_is_site(part.positions[i])) mine.push_back(rec[i]);
                       });
        return mine;
      });
  std::set<std::uint64_t> all;
  for (const auto& v : per_rank)
    for (const std::uint64_t r : v) EXPECT_TRUE(all.insert(r).second) << "record " << r << " twice";
  return all;
}

TEST(TileSites, EveryStrideThPointOfTheWholeCloudsOrderIsASiteForAnyProcessCount) {
  const PointCloud c = clumps(20000, 4);
  for (const double cell : {0.9, 0.2})
    for (const std::uint64_t stride : {2u, 5u}) {
      const std::vector<std::uint32_t> order = index_order(c, cell);
      std::set<std::uint64_t> expected;
      for (std::size_t s = 0; s < order.size(); s += stride) expected.insert(order[s]);
      for (const int ranks : {1, 3})
        EXPECT_EQ(marked_sites(c, cell, stride, ranks), expected)
            << "cell " << cell << ", stride " << stride << ", " << ranks << " processes";
    }
}

TEST(TileSites, TheSiteCellIsTheScalePhasesFirstIndexWhenItServesH) {
  const double h0 = 0.02;
  // r_est whose index of 1.6 r_est serves both h0 and h: that index.
  EXPECT_DOUBLE_EQ(kernel_site_cell(0.025, h0, 0.016), 0.016 * 1.6);
  EXPECT_TRUE(grid_serves(kernel_site_cell(0.025, h0, 0.016), 0.025));
  // 1.6 r_est too small for h0: the index of h0, kept when it serves h (the scale test lowered
  // h a little below h0), else one of h's own.
  EXPECT_DOUBLE_EQ(kernel_site_cell(0.019, h0, 0.005), grid_cell_for(h0));
  EXPECT_DOUBLE_EQ(kernel_site_cell(0.025, h0, 0.005), grid_cell_for(0.025));
  // h raised far above h0 (noise): neither serves, an index of h's own.
  EXPECT_DOUBLE_EQ(kernel_site_cell(0.08, h0, 0.016), grid_cell_for(0.08));
  // No first index (a fixed or adaptive h).
  EXPECT_DOUBLE_EQ(kernel_site_cell(0.025, h0, 0), grid_cell_for(0.025));
}

}  // namespace
}  // namespace scanclean::detail

// The first passes of a tiled run (filter/src/tile_globals.h): the global choices do not depend
// on how many processes read the input or how it is chunked, the arrays present are those of
// any process's records, and a bad record is refused naming it. (Against the in-memory filter's
// own choices: tiled_filter_test.cpp.)
#include "../../filter/src/tile_globals.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <limits>
#include <string>
#include <vector>

#include "../../filter/src/tile_exchange.h"
#include "scanclean/core/errors.h"
#include "support/synthetic.h"
#include "tiled_test_support.h"

namespace scanclean::detail {
namespace {

// A noisy floor with a sphere on it and clutter.
PointCloud floor_scene(std::uint32_t seed) {
  PointCloud c = test::noisy_plane(12000, 4.0, 0.01, seed);
  PointCloud s = test::noisy_sphere(2000, 0.7, 0.01, seed + 1);
  append(c, s);
  test::add_uniform_outliers(c, 150, -2.0, 2.0, seed + 2);
  c.normals.clear();
  return c;
}

// The passes as `ranks` processes reading `chunk` records at a time (colours only in the chunks
// from record `colours_from` on, when > 0).
GlobalPasses passes(const PointCloud& c, const FilterOptions& o, int ranks, std::size_t chunk,
                    std::size_t colours_from = 0) {
  TiledSource src = test::source_of(c);
  if (colours_from > 0) {
    const auto read = src.read;
    src.read = [read, colours_from](std::uint64_t first, std::uint64_t count, PointCloud& out,
                                    std::vector<std::uint64_t>& rec) {
      read(first, count, out, rec);
      if (first < colours_from) out.colors.clear();
    };
  }
  const std::vector<GlobalPasses> all =
      test::run_ranks<GlobalPasses>(ranks, [&](const TileComm& comm) {
        return global_passes(src, o, 4.0, record_range(src.records, comm), chunk, comm, nullptr);
      });
  // Every process makes the same choices.
  for (const GlobalPasses& g : all) {
    EXPECT_EQ(g.globals.h, all[0].globals.h);
    EXPECT_EQ(g.globals.box.min(), all[0].globals.box.min());
    EXPECT_EQ(g.histogram, all[0].histogram);
  }
  return all[0];
}

void expect_same(const GlobalPasses& a, const GlobalPasses& b, const std::string& what) {
  SCOPED_TRACE(what);
  const TiledGlobals &x = a.globals, &y = b.globals;
  EXPECT_EQ(x.points, y.points);
  EXPECT_EQ(x.box.min(), y.box.min());
  EXPECT_EQ(x.box.max(), y.box.max());
  EXPECT_EQ(x.h, y.h);
  EXPECT_EQ(x.h0, y.h0);
  EXPECT_EQ(x.noise_sigma, y.noise_sigma);
  EXPECT_EQ(x.noise_sigma_h0, y.noise_sigma_h0);
  EXPECT_EQ(x.h_noise, y.h_noise);
  EXPECT_EQ(x.merge_eps, y.merge_eps);
  EXPECT_EQ(x.kernel_stride, y.kernel_stride);
  EXPECT_EQ(x.min_component_size, y.min_component_size);
  EXPECT_EQ(x.halo, y.halo);
  EXPECT_EQ(a.r_est, b.r_est);
  EXPECT_EQ(a.histogram, b.histogram);
  EXPECT_EQ(a.columns.bytes(), b.columns.bytes());
}

TEST(TileGlobals, TheChoicesDoNotDependOnTheProcessesOrTheChunks) {
  const PointCloud c = floor_scene(3);
  // Fewer neighbours than the defaults' 96, so that the processes exchange less (every sample's
  // distances to its neighbours).
  FilterOptions automatic, adaptive;
  automatic.k_h = 32;
  adaptive.scale = ScaleMode::kAdaptive;
  adaptive.k_adaptive = 32;
  for (const FilterOptions& o : {automatic, adaptive}) {
    const GlobalPasses one = passes(c, o, 1, 1 << 20);
    ASSERT_EQ(one.globals.points, c.size());
    EXPECT_GT(one.globals.h, 0);
    EXPECT_GT(one.globals.halo, one.globals.h);
    std::uint64_t in_histogram = 0;
    for (const std::uint64_t n : one.histogram) in_histogram += n;
    EXPECT_EQ(in_histogram, c.size());
    if (o.scale == ScaleMode::kAuto) {
      EXPECT_GT(one.r_est, 0);
      EXPECT_GT(one.globals.noise_sigma, 0.005);  // the floor's and sphere's 0.01 m, estimated
      EXPECT_LT(one.globals.noise_sigma, 0.02);
    } else {
      EXPECT_EQ(one.r_est, 0);
    }
    expect_same(one, passes(c, o, 1, 997), "one process, chunks of 997 records");
    expect_same(one, passes(c, o, 3, 4001), "three processes");
  }
}

TEST(TileGlobals, TheArraysPresentAreThoseOfAnyProcesssRecords) {
  PointCloud c = floor_scene(4);
  for (std::size_t i = 0; i < c.size(); ++i)
    c.colors.push_back({static_cast<std::uint8_t>(i % 256), 80, 160, 255});
  FilterOptions fixed;  // (the arrays are found in the first pass: no neighbours needed)
  fixed.scale = ScaleMode::kFixed;
  fixed.h = 0.1;
  // Only the last process's records (of three) carry colours.
  const std::uint64_t last_range = record_range(c.size(), test::process_of(2, 3))[0];
  const GlobalPasses g = passes(c, fixed, 3, 5000, last_range);
  EXPECT_TRUE(g.columns.colors);
  EXPECT_FALSE(g.columns.normals);
  EXPECT_FALSE(g.columns.confidences);
  const GlobalPasses none = passes(c, fixed, 3, 5000, c.size());
  EXPECT_FALSE(none.columns.colors);
}

// One process of a run that counts its messages' bytes and its sums of whole arrays.
struct RankRun {
  GlobalPasses g;
  std::size_t largest_message = 0;
  int sums = 0;
};

// The passes as `ranks` processes reading 5,000 records at a time, each counting its messages'
// bytes and its sums of whole arrays.
std::vector<RankRun> counted_passes(const PointCloud& c, const FilterOptions& o, int ranks) {
  const TiledSource src = test::source_of(c);
  return test::run_ranks<RankRun>(ranks, [&](const TileComm& comm) {
    RankRun run;
    TileComm counted = comm;
    counted.allgather = [&](const std::string& mine) {
      run.largest_message = std::max(run.largest_message, mine.size());
      return comm.allgather(mine);
    };
    counted.sum = [&](std::vector<std::uint64_t>& counts) {
      ++run.sums;
      comm.sum(counts);
    };
    run.g = global_passes(src, o, 4.0, record_range(src.records, comm), 5000, counted, nullptr);
    return run;
  });
}

// Every process receives every process's messages: a histogram travels as its occupied cells,
// not as the grid's (about 2 million) cells, so that the exchange does not grow each process's
// memory by 16 MB a process.
TEST(TileGlobals, TheHistogramTravelsAsItsOccupiedCells) {
  const PointCloud c = floor_scene(6);
  FilterOptions fixed;  // no neighbour distances travel with it
  fixed.scale = ScaleMode::kFixed;
  fixed.h = 0.1;
  const std::vector<RankRun> runs = counted_passes(c, fixed, 3);
  const GlobalPasses& g = runs[0].g;
  std::size_t occupied = 0;
  for (const std::uint64_t n : g.histogram) occupied += n > 0 ? 1 : 0;
  ASSERT_GT(g.histogram.size(), 20 * occupied) << "the scene fills too much of its grid";
  for (const RankRun& r : runs) {
    EXPECT_EQ(r.g.histogram, g.histogram);
    // At most every occupied cell (16 bytes each) and the first pass's samples (24 bytes each).
    EXPECT_LE(r.largest_message, 16 * occupied + 24 * 10000 + 1024);
    EXPECT_EQ(r.sums, 0) << "the whole arrays were summed for a sparse histogram";
  }
}

// Where every process's records spread over the whole scene and fill much of its grid (a flat
// floor: 256 x 256 x 2 cells), the occupied cells gathered would outweigh the array: the arrays
// are summed instead (MPI_Allreduce), once, and give the same counts as one process.
TEST(TileGlobals, ADenseHistogramIsSummedAsAnArray) {
  const PointCloud c = test::noisy_plane(150000, 4.0, 0.002, 8);  // records in random places
  FilterOptions fixed;
  fixed.scale = ScaleMode::kFixed;
  fixed.h = 0.1;
  const GlobalPasses one = passes(c, fixed, 1, 1 << 20);
  std::size_t occupied = 0;
  for (const std::uint64_t n : one.histogram) occupied += n > 0 ? 1 : 0;
  const std::vector<RankRun> runs = counted_passes(c, fixed, 3);
  for (const RankRun& r : runs) {
    EXPECT_EQ(r.g.histogram, one.histogram);
    EXPECT_EQ(r.sums, 1);
    // Only the first pass's samples travel by allgather, not the histogram's occupied cells.
    EXPECT_LT(r.largest_message, 16 * occupied / 3);
  }
}

TEST(TileGlobals, ABadRecordIsRefusedNamingItBeforeAnyChoice) {
  PointCloud c = floor_scene(5);
  c.positions[10011].y() = std::numeric_limits<double>::quiet_NaN();
  try {
    passes(c, {}, 2, 3000);
    ADD_FAILURE() << "a non-finite coordinate passed";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("record 10011"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace scanclean::detail

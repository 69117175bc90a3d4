// The tiled, out-of-core filter (tiled_filter.h) against the in-memory filter on a cloud split
// into many tiles.
#include "scanclean/filter/tiled_filter.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <limits>
#include <map>
#include <mutex>
#include <random>
#include <stdexcept>
#include <thread>

#include "scanclean/core/errors.h"
#include "support/filter_outputs.h"
#include "support/synthetic.h"
#include "tiled_test_support.h"

namespace scanclean {
namespace {

namespace fs = std::filesystem;

// A 12 m x 12 m noisy floor with a row of noisy half-spheres on it and uniform clutter above.
PointCloud scene(std::uint32_t seed) {
  PointCloud c = test::noisy_plane(40000, 12.0, 0.01, seed);
  for (int k = 0; k < 4; ++k) {
    PointCloud s = test::noisy_sphere(3000, 0.8, 0.01, seed + 1 + static_cast<std::uint32_t>(k));
    for (auto& p : s.positions) p += Eigen::Vector3d(-4.5 + 3.0 * k, 2.0, 0.0);
    append(c, s);
  }
  test::add_uniform_outliers(c, 800, -6.0, 6.0, seed + 9);
  c.normals.clear();  // raw scanner points: no sensor normals
  return c;
}

using test::source_of;

using test::ScratchDir;

struct Tiled {
  TiledStats stats;
  PointCloud cloud, outliers;
  std::size_t sink_calls = 0;
};

Tiled run_tiled(const PointCloud& c, const FilterOptions& o, std::uint64_t max_tile_points) {
  const ScratchDir scratch("test");
  Tiled r;
  r.stats = tiled_filter(source_of(c), o, scratch.options(max_tile_points),
                         [&](std::size_t, const PointCloud& a, const PointCloud& b) {
                           append(r.cloud, a);
                           append(r.outliers, b);
                           ++r.sink_calls;
                         });
  EXPECT_TRUE(fs::is_empty(scratch.path)) << "scratch files left behind";
  return r;
}

struct Diff {
  std::size_t only_one = 0, outlier_diff = 0, flags_differ = 0, moved = 0;
  double largest = 0;  //!< metres
};

// The output seeds in one run only, the outliers in one run only, the flags and positions that
// differ between the in-memory and the tiled result (printed, in units of h).
Diff compare(const FilterResult& mem, const Tiled& tiled, double h) {
  Diff d;
  const auto a = test::by_source(mem.cloud), b = test::by_source(tiled.cloud);
  const auto ao = test::by_source(mem.outliers), bo = test::by_source(tiled.outliers);
  // Every input point is an output seed, an outlier or merged, once, in both runs.
  for (const auto& [s, k] : bo) EXPECT_EQ(b.count(s), 0u);
  for (const auto& [s, k] : a) {
    const auto it = b.find(s);
    if (it == b.end()) {
      ++d.only_one;
      continue;
    }
    const double dist = (mem.cloud.positions[k] - tiled.cloud.positions[it->second]).norm();
    d.largest = std::max(d.largest, dist);
    d.moved += dist > 0 ? 1 : 0;
    d.flags_differ += mem.cloud.find_attribute("flags")->values[k] !=
                      tiled.cloud.find_attribute("flags")->values[it->second];
  }
  for (const auto& [s, k] : b) d.only_one += a.count(s) ? 0 : 1;
  for (const auto& [s, k] : ao) d.outlier_diff += bo.count(s) ? 0 : 1;
  for (const auto& [s, k] : bo) d.outlier_diff += ao.count(s) ? 0 : 1;
  std::printf(
      "tiles %zu, points out %zu (in memory %zu); seeds in one run only %zu, outliers in one run "
      "only %zu, flags differ %zu, positions differ %zu, largest difference %.3g h\n",
      tiled.stats.tiles, tiled.cloud.size(), mem.cloud.size(), d.only_one, d.outlier_diff,
      d.flags_differ, d.moved, d.largest / h);
  return d;
}

// What a tiled run at kernel stride 2 may differ in from the in-memory run with the same
// options (KernelStrideTakesTheWholeCloudsSubsampleInEveryTile says why): a few density-test
// decisions near the threshold, and positions by the summation order only.
void expect_agreement_at_stride(const Diff& d, std::size_t points, double h) {
  const double n = static_cast<double>(points);
  EXPECT_LE(static_cast<double>(d.only_one), 1.5e-3 * n);
  EXPECT_LE(static_cast<double>(d.outlier_diff), 1.5e-3 * n);
  EXPECT_LE(static_cast<double>(d.flags_differ), 1e-3 * n);
  EXPECT_LT(d.largest, 1e-3 * h);
}

TEST(TiledFilter, GlobalScaleFromTheFirstPassMatchesTheInMemoryFilter) {
  const PointCloud c = scene(5);
  const FilterResult mem = robust_filter(c);
  const Tiled tiled = run_tiled(c, {}, 14000);
  std::printf(
      "in memory %.2f s; tiled: %zu tiles, %llu halo points, largest %llu, h %.4f, "
      "first pass %.2f s, distribution %.2f s, tiles %.2f s\n",
      mem.stats.seconds_total, tiled.stats.tiles,
      static_cast<unsigned long long>(tiled.stats.halo_points),
      static_cast<unsigned long long>(tiled.stats.tile_points_max), tiled.stats.globals.h,
      tiled.stats.seconds_globals, tiled.stats.seconds_distribute, tiled.stats.seconds_tiles);
  // h0 is computed from the same float distances: bit-identical.
  EXPECT_EQ(tiled.stats.globals.h0, mem.stats.h0);
  // The noise estimate and the scale test sum the same neighbours in another order.
  EXPECT_NEAR(tiled.stats.globals.noise_sigma, mem.stats.noise_sigma, 1e-9 * mem.stats.h);
  EXPECT_NEAR(tiled.stats.globals.h, mem.stats.h, 1e-9 * mem.stats.h);
  EXPECT_EQ(tiled.stats.globals.kernel_stride, mem.stats.kernel_stride);
  EXPECT_EQ(tiled.stats.globals.merge_eps, mem.stats.merge_eps);
}

TEST(TiledFilter, ManyTilesGiveTheInMemoryResultUpToTheStatedDifferences) {
  const PointCloud c = scene(5);
  // Kernels at every point, so that the kernel stride's subsample is not one of the
  // differences; h as the tiled run's first pass chooses it. With the crease split, which needs
  // the whole cloud's noise estimate in the tiles (refit_noise_sigma).
  FilterOptions o;
  o.kernel_stride = 1;
  o.crease_spread = 1.1;
  const Tiled tiled = run_tiled(c, o, 14000);
  EXPECT_GE(tiled.stats.tiles, 8u);
  EXPECT_EQ(tiled.sink_calls, tiled.stats.tiles);
  EXPECT_GT(tiled.stats.halo_points, 0u);
  EXPECT_LE(tiled.stats.tile_points_max, 14000u * 3 / 2);  // histogram cells: an estimate
  EXPECT_EQ(tiled.stats.points_out, tiled.cloud.size());
  FilterOptions fixed = o;
  fixed.scale = ScaleMode::kFixed;
  fixed.h = tiled.stats.globals.h;
  fixed.merge_eps = tiled.stats.globals.merge_eps;
  fixed.refit_noise_sigma = tiled.stats.globals.noise_sigma;  // the crease split's, as the tiles'
  const FilterResult mem = robust_filter(c, fixed);
  EXPECT_GT(mem.stats.kernels_split, 0u);

  const Diff d = compare(mem, tiled, fixed.h);
  const std::size_t only_one = d.only_one, outlier_diff = d.outlier_diff,
                    flags_differ = d.flags_differ;
  const double largest = d.largest;
  // The stated reasons (tiled_filter.h) leave summation-order differences far below the noise,
  // and a handful of border and threshold decisions.
  const double n = static_cast<double>(c.size());
  // (Measured: 0 seeds, 0 outliers and 0 flags differ; positions by at most 1e-5 h.)
  EXPECT_LE(static_cast<double>(only_one), 1e-3 * n);
  EXPECT_LE(static_cast<double>(outlier_diff), 1e-3 * n);
  EXPECT_LE(static_cast<double>(flags_differ), 1e-3 * n);
  EXPECT_LT(largest, 1e-3 * fixed.h);
}

TEST(TiledFilter, TheRefitActsInTilesAsInMemory) {
  // The half-spheres meet the floor at a crease: the sheet refit acts there (and the crease
  // split at a few kernels). The tiles run with the whole cloud's h fixed and get
  // its noise estimate for both (refit_noise_sigma); against the in-memory run with the same
  // options (automatic h, its own estimate). Kernels at every 2nd point, as in the test below (it
  // states what else differs), keep the test short.
  const PointCloud c = scene(5);
  FilterOptions o;
  o.kernel_stride = 2;
  o.refit_spread = 1.1;
  o.crease_spread = 1.1;
  const Tiled tiled = run_tiled(c, o, 14000);
  const FilterResult mem = robust_filter(c, o);
  EXPECT_GT(mem.stats.kernels_refitted, 100u);
  EXPECT_NEAR(tiled.stats.globals.noise_sigma, mem.stats.noise_sigma, 1e-9 * mem.stats.h);
  const double h = mem.stats.h;
  const Diff d = compare(mem, tiled, h);
  expect_agreement_at_stride(d, c.size(), h);
  // The tiles did split and refit: their output is not the one without either.
  FilterOptions plain = o;
  plain.refit_spread = 0;
  plain.crease_spread = 0;
  const Diff p = compare(robust_filter(c, plain), tiled, h);
  EXPECT_GT(p.moved, 100u);
  EXPECT_GT(p.largest, 1e-3 * h);
  // A fixed h has no noise estimate of its own: without refit_noise_sigma, neither acts.
  FilterOptions fixed = o;
  fixed.scale = ScaleMode::kFixed;
  fixed.h = h;
  const FilterResult f = robust_filter(c, fixed);
  EXPECT_EQ(f.stats.kernels_refitted, 0u);
  EXPECT_EQ(f.stats.kernels_split, 0u);
}

TEST(TiledFilter, KernelStrideTakesTheWholeCloudsSubsampleInEveryTile) {
  // Kernels at every 2nd point of the whole cloud's grid order: each tile must put them at the
  // same points as the in-memory run (a tile's own grid order would pick another half).
  const PointCloud c = scene(5);
  FilterOptions o;
  o.kernel_stride = 2;
  const Tiled tiled = run_tiled(c, o, 14000);
  EXPECT_GE(tiled.stats.tiles, 8u);
  EXPECT_EQ(tiled.stats.globals.kernel_stride, 2);
  // Against the in-memory run with the same options (automatic h): its kernel phase's grid
  // is sized by the scale phase's first estimate, which the first pass reproduces.
  const FilterResult mem = robust_filter(c, o);
  EXPECT_EQ(mem.stats.kernel_stride, 2);
  EXPECT_NEAR(tiled.stats.globals.h, mem.stats.h, 1e-9 * mem.stats.h);
  const double h = mem.stats.h;
  const Diff d = compare(mem, tiled, h);
  // The same kernels: positions differ by the summation order only (far below the noise).
  // What remains are density-test decisions near the threshold: that test also thins the
  // output points by the stride, in each tile's grid order (docs/SCALING.md). Measured: 24
  // seeds and 28 outliers in one run only, 0 flags, 9e-5 h; with each tile's own subsample
  // (before): 2,122 seeds, 348 outliers, 17 flags, 0.17 h.
  expect_agreement_at_stride(d, c.size(), h);
}

// A non-finite coordinate is refused in the first pass, naming its record, before any grid or
// index casts it to a cell (as robust_filter refuses it before its index).
TEST(TiledFilter, ANonFiniteCoordinateIsRefusedNamingItsRecord) {
  // Record 12346 is not among the first pass's samples of h (every 3rd record of 30,000).
  PointCloud c = test::noisy_plane(30000, 3.0, 0.01, 11);
  c.positions[12346].y() = std::numeric_limits<double>::quiet_NaN();
  const ScratchDir scratch("nan");
  std::size_t sink_calls = 0;
  try {
    tiled_filter(source_of(c), {}, scratch.options(8000),
                 [&](std::size_t, const PointCloud&, const PointCloud&) { ++sink_calls; });
    ADD_FAILURE() << "no error for a NaN coordinate";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("record 12346"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("non-finite"), std::string::npos) << e.what();
  }
  EXPECT_EQ(sink_calls, 0u);
  EXPECT_TRUE(fs::is_empty(scratch.path));
}

// A confidence outside [0, 1], where confidences are the weights, is refused the same way.
TEST(TiledFilter, AConfidenceOutsideTheUnitIntervalIsRefusedNamingItsRecord) {
  PointCloud c = test::noisy_plane(30000, 3.0, 0.01, 12);
  c.confidences.assign(c.size(), 0.5f);
  c.confidences[20001] = 1.5f;  // not a sample of h either
  const ScratchDir scratch("conf");
  EXPECT_THROW(
      {
        try {
          tiled_filter(source_of(c), {}, scratch.options(8000),
                       [](std::size_t, const PointCloud&, const PointCloud&) {});
        } catch (const InputError& e) {
          EXPECT_NE(std::string(e.what()).find("record 20001: confidence 1.5 outside [0, 1]"),
                    std::string::npos)
              << e.what();
          throw;
        }
      },
      InputError);
  EXPECT_TRUE(fs::is_empty(scratch.path));
}

// Three processes (threads) that take the tiles as they become free (TileComm::take) or
// filter the plan's share: every tile is filtered exactly once, and each tile's result is the
// same as one process's, bit for bit. (The order they are taken in: tile_plan_test.cpp.)
TEST(TiledFilter, TilesTakenAsProcessesBecomeFreeGiveTheSameResults) {
  PointCloud c = test::noisy_plane(10000, 6.0, 0.01, 31);
  test::add_uniform_outliers(c, 100, -3.0, 3.0, 32);
  c.normals.clear();
  const ScratchDir scratch("take");
  struct TileResult {
    std::size_t tile;
    PointCloud cloud, outliers;
  };
  // Each tile's result over all processes; `taken`: the order the tiles were filtered in.
  const auto run = [&](int ranks, bool take, std::vector<std::size_t>* taken) {
    std::mutex m;
    std::map<std::size_t, TileResult> by_tile;
    std::size_t duplicates = 0;
    std::atomic<std::size_t> takes{0};
    test::run_ranks<int>(ranks, [&](const TileComm& comm) {
      TileComm used = comm;
      used.take = take ? std::function<std::uint64_t()>([&, comm] {
        ++takes;
        return comm.take();
      })
                       : nullptr;
      tiled_filter(
          source_of(c), {}, scratch.options(2500),
          [&](std::size_t k, const PointCloud& a, const PointCloud& b) {
            const std::lock_guard lock(m);
            duplicates += by_tile.count(k);
            by_tile[k] = TileResult{k, a, b};
            if (taken) taken->push_back(k);
          },
          used);
      return 0;
    });
    EXPECT_EQ(duplicates, 0u) << ranks << " processes: a tile filtered twice";
    // Taking: one take per tile, and one more per process that found none left.
    EXPECT_EQ(takes.load(), take ? by_tile.size() + static_cast<std::size_t>(ranks) : 0u);
    return by_tile;
  };
  const auto one = run(1, false, nullptr);
  ASSERT_GE(one.size(), 6u) << "too few tiles to share";
  std::vector<std::size_t> order;
  for (const bool take : {false, true}) {
    SCOPED_TRACE(take ? "taken as free" : "dealt by the plan");
    const auto three = run(3, take, take ? &order : nullptr);
    ASSERT_EQ(three.size(), one.size());
    for (const auto& [k, r] : one) {
      const TileResult& t = three.at(k);
      EXPECT_EQ(t.cloud.positions, r.cloud.positions) << "tile " << k;
      EXPECT_EQ(t.outliers.positions, r.outliers.positions) << "tile " << k;
      ASSERT_EQ(t.cloud.attributes.size(), r.cloud.attributes.size());
      for (std::size_t a = 0; a < r.cloud.attributes.size(); ++a)
        EXPECT_EQ(t.cloud.attributes[a].values, r.cloud.attributes[a].values) << "tile " << k;
    }
  }
  EXPECT_EQ(order.size(), one.size()) << "a tile's sink called twice or never";
  EXPECT_TRUE(fs::is_empty(scratch.path)) << "scratch files left behind";
}

// A run that ends by an exception after the distribution (here the sink's, as when the output
// disk fills) leaves no scratch files behind: the tiles not yet filtered had theirs.
TEST(TiledFilter, AFailedRunLeavesNoScratchFiles) {
  const PointCloud c = test::noisy_plane(30000, 3.0, 0.01, 13);
  const ScratchDir scratch("fail");
  std::size_t sink_calls = 0;
  EXPECT_THROW(tiled_filter(source_of(c), {}, scratch.options(4000),
                            [&](std::size_t, const PointCloud&, const PointCloud&) {
                              if (++sink_calls == 2) throw std::runtime_error("sink: disk full");
                            }),
               std::runtime_error);
  EXPECT_EQ(sink_calls, 2u);
  EXPECT_TRUE(fs::is_empty(scratch.path)) << "scratch files left behind";
}

// Two processes (threads here); process 1's sink fails on its first tile while process 0 sits in
// its own first tile's sink, as a process that scanclean-mpi's abort will stop there: by the
// time process 1's call has thrown, no scratch file of either process is left, those of process
// 0's tiles included (process 0 would never remove them).
TEST(TiledFilter, AFailedProcessRemovesEveryProcesssScratchFiles) {
  const PointCloud c = test::noisy_plane(30000, 3.0, 0.01, 13);
  const ScratchDir scratch("fail2");
  test::RankExchange exchange(2);
  std::mutex m;
  std::condition_variable cv;
  bool in_sink0 = false, release0 = false;
  std::size_t left_when_failed = 0;
  std::thread rank0([&] {
    const TileComm comm = exchange.comm(0);
    try {
      tiled_filter(
          source_of(c), {}, scratch.options(4000),
          [&](std::size_t, const PointCloud&, const PointCloud&) {
            std::unique_lock lock(m);
            in_sink0 = true;
            cv.notify_all();
            cv.wait(lock, [&] { return release0; });
          },
          comm);
    } catch (const std::exception&) {  // ended by the other's failure, as intended
    }
  });
  const TileComm comm = exchange.comm(1);
  std::size_t sink1 = 0;
  EXPECT_THROW(
      tiled_filter(
          source_of(c), {}, scratch.options(4000),
          [&](std::size_t, const PointCloud&, const PointCloud&) {
            ++sink1;
            {  // process 0 is in its sink, holding its other tiles' files
              std::unique_lock lock(m);
              EXPECT_TRUE(cv.wait_for(lock, std::chrono::minutes(2), [&] { return in_sink0; }))
                  << "process 0 never reached its sink";
            }
            throw std::runtime_error("sink: disk full");
          },
          comm),
      std::runtime_error);
  for (auto it = fs::directory_iterator(scratch.path); it != fs::directory_iterator(); ++it)
    ++left_when_failed;
  {
    const std::lock_guard lock(m);
    release0 = true;
  }
  exchange.fail();
  cv.notify_all();
  rank0.join();
  EXPECT_EQ(sink1, 1u);
  EXPECT_EQ(left_when_failed, 0u) << "scratch files left behind by the failed process";
}

// The input's own attributes (a scanner's classification, GPS time, a label named like an
// output) reach the tiled outputs as they reach the in-memory ones: same names, order and types,
// and each output point and outlier holds its input point's values.
TEST(TiledFilter, InputAttributesReachTheOutputsAsInMemory) {
  PointCloud c = scene(7);
  std::vector<double> cls(c.size()), time(c.size()), flags(c.size());
  for (std::size_t i = 0; i < c.size(); ++i) {
    cls[i] = static_cast<double>(i % 7);
    time[i] = 1.0e9 + 0.001 * static_cast<double>(i);  // needs a double
    flags[i] = 200;  // named like an output: the filter's flags take its place
  }
  c.set_attribute("classification", AttributeType::kUInt8, cls);
  c.set_attribute("flags", AttributeType::kUInt8, flags);
  c.set_attribute("gps_time", AttributeType::kFloat64, time);
  FilterOptions o;
  o.kernel_stride = 1;
  const Tiled tiled = run_tiled(c, o, 14000);
  ASSERT_GE(tiled.stats.tiles, 8u);
  FilterOptions fixed = o;
  fixed.scale = ScaleMode::kFixed;
  fixed.h = tiled.stats.globals.h;
  fixed.merge_eps = tiled.stats.globals.merge_eps;
  const FilterResult mem = robust_filter(c, fixed);
  auto names = [](const PointCloud& p) {
    std::vector<std::pair<std::string, AttributeType>> v;
    for (const Attribute& a : p.attributes) v.emplace_back(a.name, a.type);
    return v;
  };
  ASSERT_FALSE(tiled.cloud.attributes.empty());
  EXPECT_EQ(names(tiled.cloud), names(mem.cloud));
  EXPECT_EQ(names(tiled.outliers), names(mem.outliers));
  EXPECT_EQ(tiled.cloud.attributes.front().name, "classification");
  for (const PointCloud* out : {&tiled.cloud, &tiled.outliers}) {
    ASSERT_GT(out->size(), 0u);
    const Attribute* si = out->find_attribute("source_index");
    const Attribute* oc = out->find_attribute("classification");
    const Attribute* ot = out->find_attribute("gps_time");
    const Attribute* of = out->find_attribute("flags");
    ASSERT_TRUE(si && oc && ot && of);
    for (std::size_t k = 0; k < out->size(); ++k) {
      const auto s = static_cast<std::size_t>(si->values[k]);
      ASSERT_EQ(oc->values[k], cls[s]) << "point " << k;
      ASSERT_EQ(ot->values[k], time[s]) << "point " << k;
      ASSERT_NE(of->values[k], 200.0) << "the filter's flags, not the input's";
    }
  }
}

}  // namespace
}  // namespace scanclean

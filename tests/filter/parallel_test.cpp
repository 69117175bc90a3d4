// The filter's parallel helpers (filter/src/parallel.h) against serial loops (the oracles): the
// lists and counts of indices with a property, the first such index, the bounding box and the
// median, on arrays of a few chunks and of many, with one and two threads; the radix selection
// against std::nth_element.

#include "../../filter/src/parallel.h"

#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

namespace scanclean::detail {
namespace {

TEST(ParallelTest, IndicesCountAndFirstMatchASerialScan) {
  std::mt19937 rng(61);  // seed 61
  for (const std::size_t n :
       {std::size_t{0}, std::size_t{1}, std::size_t{5000}, std::size_t{1} << 20}) {
    for (const double share : {0.0, 0.001, 0.5, 1.0}) {
      std::bernoulli_distribution pick(share);
      std::vector<std::uint8_t> flag(n);
      for (auto& f : flag) f = pick(rng) ? 1 : 0;
      auto pred = [&](std::size_t i) { return flag[i] != 0; };
      std::vector<std::uint32_t> want;
      for (std::size_t i = 0; i < n; ++i)
        if (flag[i]) want.push_back(static_cast<std::uint32_t>(i));
      const std::size_t first = want.empty() ? n : want.front();
      for (const int threads : {1, 2}) {
        tbb::task_arena(threads).execute([&] {
          EXPECT_EQ(indices_where(n, pred), want) << n << " " << share << " " << threads;
          EXPECT_EQ(count_where(n, pred), want.size()) << n << " " << share << " " << threads;
          EXPECT_EQ(first_where(n, pred), first) << n << " " << share << " " << threads;
        });
      }
    }
  }
}

TEST(ParallelTest, FirstWhereFindsTheEarliestOfSeveralLateOnes) {
  const std::size_t n = std::size_t{1} << 20;
  for (const std::size_t at : {std::size_t{0}, std::size_t{4095}, std::size_t{4096}, n - 1}) {
    // Matches at `at` and at every index past the middle: the earliest must win whatever range
    // a thread scans first.
    auto pred = [&](std::size_t i) { return i == at || i > n / 2; };
    for (const int threads : {1, 2})
      tbb::task_arena(threads).execute(
          [&] { EXPECT_EQ(first_where(n, pred), std::min(at, n / 2 + 1)); });
  }
}

TEST(ParallelTest, BoundingBoxAndMedianMatchSerialOnes) {
  std::mt19937 rng(67);  // seed 67
  std::normal_distribution<double> g(0.0, 3.0);
  for (const std::size_t n : {std::size_t{1}, std::size_t{777}, std::size_t{200000}}) {
    std::vector<Eigen::Vector3d> p(n);
    for (auto& x : p) {
      const double c = -5 * g(rng), b = 10 + g(rng), a = g(rng);  // gcc's order
      x = Eigen::Vector3d(a, b, c);
    }
    Eigen::AlignedBox3d want;
    for (const auto& x : p) want.extend(x);
    std::vector<double> d(n);
    for (std::size_t i = 0; i < n; ++i) d[i] = p[i].x();
    std::vector<double> sorted = d;
    std::sort(sorted.begin(), sorted.end());
    for (const int threads : {1, 2}) {
      tbb::task_arena(threads).execute([&] {
        const Eigen::AlignedBox3d got = bounding_box_of(p);
        EXPECT_EQ(got.min(), want.min()) << n;
        EXPECT_EQ(got.max(), want.max()) << n;
        EXPECT_EQ(median_of(d), sorted[(n - 1) / 2]) << n;
      });
    }
  }
  EXPECT_TRUE(bounding_box_of(std::vector<Eigen::Vector3d>{}).isEmpty());
  EXPECT_EQ(median_of(std::vector<double>{}), 0.0);
  EXPECT_EQ(median_of(std::vector<std::size_t>{5, 1, 4, 2}), 2u);  // the lower median
}

// radix_select against std::nth_element (the oracle) on arrays below and above the size where
// it narrows in parallel: wide ranges with both signs, a narrow range (many values share their
// leading key bits), many ties, all values equal; at the ends, the median and random ranks; with
// one and two threads.
template <class T>
void check_radix_select(std::uint32_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<T> wide(0, 1000);
  std::uniform_real_distribution<T> narrow(T(0.0125), T(0.0126));
  std::uniform_int_distribution<int> few(-3, 3);
  for (const std::size_t n : {std::size_t{1}, std::size_t{1000}, std::size_t{300000}}) {
    for (int kind = 0; kind < 4; ++kind) {
      std::vector<T> v(n);
      for (T& x : v)
        x = kind == 0 ? wide(rng) : kind == 1 ? narrow(rng) : kind == 2 ? T(few(rng)) / 8 : T(7);
      std::vector<std::size_t> ranks = {0, n - 1, (n - 1) / 2};
      for (int r = 0; r < 5; ++r) ranks.push_back(rng() % n);
      for (const std::size_t k : ranks) {
        std::vector<T> sorted = v;
        std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(k),
                         sorted.end());
        for (const int threads : {1, 2}) {
          const std::vector<T> before = v;
          T got = 0;
          tbb::task_arena(threads).execute([&] { got = radix_select(v, k); });
          EXPECT_EQ(got, sorted[k])
              << n << " values, kind " << kind << ", rank " << k << ", " << threads << " threads";
          EXPECT_EQ(v, before) << "the input is not changed";
        }
      }
    }
  }
}

TEST(ParallelTest, RadixSelectMatchesNthElement) {
  check_radix_select<float>(53);   // seed 53
  check_radix_select<double>(59);  // seed 59
}

}  // namespace
}  // namespace scanclean::detail

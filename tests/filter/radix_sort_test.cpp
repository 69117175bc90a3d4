// The stable radix sort (filter/src/radix_sort.h) against std::stable_sort (the oracle): narrow
// and 64-bit keys, many ties, arrays sorted in parallel chunks; and the float key's order against
// float's own.

#include "../../filter/src/radix_sort.h"

#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <utility>
#include <vector>

namespace scanclean::detail {
namespace {

TEST(RadixSortTest, StableSortMatchesStdStableSort) {
  std::mt19937_64 rng(41);  // seed 41
  for (const int bits : {0, 5, 11, 12, 33, 64}) {
    const std::uint64_t mask = bits == 64 ? ~0ULL : (std::uint64_t{1} << bits) - 1;
    std::vector<std::pair<std::uint64_t, std::uint32_t>> v(3000);
    for (std::uint32_t i = 0; i < v.size(); ++i)
      v[i] = {rng() & mask & (i % 3 == 0 ? 7 : ~0ULL), i};
    auto want = v;
    std::stable_sort(want.begin(), want.end(),
                     [](const auto& a, const auto& b) { return a.first < b.first; });
    std::vector<std::pair<std::uint64_t, std::uint32_t>> scratch;
    stable_radix_sort(
        v, [](const auto& e) { return e.first; }, scratch);
    EXPECT_EQ(v, want) << bits << " bits";
  }
}

TEST(RadixSortTest, LargeArraysSortedInChunksMatchStdStableSort) {
  // Sizes that take one chunk, several, and a last chunk of another length; keys with many ties
  // across chunks, so that stability between chunks is tested; in 1 and 2 threads.
  std::mt19937_64 rng(47);  // seed 47
  for (const std::size_t n : {65535u, 65536u * 3 + 17, 65536u * 70}) {
    std::vector<std::pair<std::uint64_t, std::uint32_t>> v(n);
    for (std::uint32_t i = 0; i < n; ++i) v[i] = {rng() % 5000, i};
    auto want = v;
    std::stable_sort(want.begin(), want.end(),
                     [](const auto& a, const auto& b) { return a.first < b.first; });
    for (const int threads : {1, 2}) {
      auto got = v;
      std::vector<std::pair<std::uint64_t, std::uint32_t>> scratch;
      tbb::task_arena arena(threads);
      arena.execute([&] {
        stable_radix_sort(
            got, [](const auto& e) { return e.first; }, scratch);
      });
      EXPECT_EQ(got, want) << n << " records, " << threads << " threads";
    }
  }
}

TEST(RadixSortTest, FloatKeysOrderAsTheFloats) {
  const float inf = std::numeric_limits<float>::infinity();
  std::vector<float> f = {-inf, -3.5f, -1e-30f, -0.0f, 0.0f, 1e-38f, 2.0f, 2.5f, 1e30f, inf};
  std::mt19937 rng(43);  // seed 43
  std::normal_distribution<float> g(0.0f, 100.0f);
  for (int i = 0; i < 500; ++i) f.push_back(g(rng));
  for (float a : f)
    for (float b : f) {
      EXPECT_EQ(float_order_key(a) < float_order_key(b), a < b) << a << " " << b;
      EXPECT_EQ(float_order_key(a) == float_order_key(b), a == b) << a << " " << b;
    }
}

}  // namespace
}  // namespace scanclean::detail

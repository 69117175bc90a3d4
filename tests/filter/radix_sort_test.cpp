// The stable radix sort (filter/src/radix_sort.h) against std::stable_sort (the oracle): narrow
// and 64-bit keys, many ties, arrays sorted in parallel chunks; and the float and double keys'
// order against the values' own.

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

// The key's order against the values' own: infinities, both zeros, denormals, extremes and
// random values.
template <class T, class Key>
void check_order_key(Key&& key, std::uint32_t seed) {
  const T inf = std::numeric_limits<T>::infinity();
  const T tiny = std::numeric_limits<T>::denorm_min(), big = std::numeric_limits<T>::max();
  std::vector<T> v = {-inf, -big, T(-3.5), -tiny, T(-0.0), T(0.0), tiny, T(2), T(2.5), big, inf};
  std::mt19937 rng(seed);
  std::normal_distribution<T> g(0, 100);
  for (int i = 0; i < 500; ++i) v.push_back(g(rng));
  for (T a : v)
    for (T b : v) {
      EXPECT_EQ(key(a) < key(b), a < b) << a << " " << b;
      EXPECT_EQ(key(a) == key(b), a == b) << a << " " << b;
    }
}

TEST(RadixSortTest, OrderKeysOrderAsTheirValues) {
  check_order_key<float>(float_order_key, 43);    // seed 43
  check_order_key<double>(double_order_key, 47);  // seed 47
}

}  // namespace
}  // namespace scanclean::detail

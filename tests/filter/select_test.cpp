// kth_smallest_below (filter/src/select.h) against std::nth_element, the oracle: random values,
// ties, values outside the stated range.

#include "../../filter/src/select.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstddef>
#include <random>
#include <vector>

namespace scanclean::detail {
namespace {

// Oracle: std::nth_element on a copy.
float nth(std::vector<float> v, std::size_t k) {
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

TEST(SelectTest, MatchesNthElementOnRandomValues) {
  std::mt19937 rng(61);  // seed 61
  for (int trial = 0; trial < 400; ++trial) {
    const std::size_t n = 1 + rng() % 600;
    const float upper = 0.5f + static_cast<float>(rng() % 1000) * 0.01f;
    // Squared distances of points in a disc (dense towards upper), with some repeated values.
    std::uniform_real_distribution<float> u(0.0f, upper);
    std::vector<float> v(n);
    for (auto& x : v) x = trial % 3 == 0 ? u(rng) : std::max(u(rng), u(rng));
    for (std::size_t i = 0; i + 1 < n; i += 7) v[i + 1] = v[i];
    const std::size_t k = rng() % n;
    std::vector<float> scratch = v;
    EXPECT_EQ(kth_smallest_below(scratch.data(), n, k, upper), nth(v, k))
        << "trial " << trial << " n " << n << " k " << k;
  }
}

TEST(SelectTest, ExactWithTiesAndValuesOutsideTheRange) {
  // All equal; clustered in one bin; values below 0 and at or above `upper` (end bins).
  std::vector<float> equal(300, 0.25f);
  for (std::size_t k : {0u, 150u, 299u}) {
    std::vector<float> s = equal;
    EXPECT_EQ(kth_smallest_below(s.data(), s.size(), k, 1.0f), 0.25f);
  }
  std::mt19937 rng(62);  // seed 62
  std::uniform_real_distribution<float> u(-0.5f, 1.5f);
  std::vector<float> v(500);
  for (auto& x : v) x = u(rng);
  for (std::size_t k = 0; k < v.size(); k += 37) {
    std::vector<float> s = v;
    EXPECT_EQ(kth_smallest_below(s.data(), s.size(), k, 1.0f), nth(v, k)) << k;
  }
  std::vector<float> s = v;  // upper <= 0: plain selection
  EXPECT_EQ(kth_smallest_below(s.data(), s.size(), 10, 0.0f), nth(v, 10));
}

}  // namespace
}  // namespace scanclean::detail

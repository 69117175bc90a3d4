#include "select.h"

#include <algorithm>
#include <array>
#include <cstdint>

namespace scanclean::detail {

float kth_smallest_below(float* v, std::size_t n, std::size_t k, float upper) {
  constexpr std::size_t kBins = 64;
  if (n <= kBins || !(upper > 0)) {
    std::nth_element(v, v + k, v + n);
    return v[k];
  }
  const float scale = static_cast<float>(kBins) / upper;
  // Monotone in x (a product with a positive constant, then clamped truncation); NaN goes last.
  auto bin = [scale](float x) -> std::size_t {
    const float t = x * scale;
    if (t >= static_cast<float>(kBins - 1) || t != t) return kBins - 1;
    return t >= 1.0f ? static_cast<std::size_t>(t) : 0;
  };
  std::array<std::uint32_t, kBins> count{};
  for (std::size_t i = 0; i < n; ++i) ++count[bin(v[i])];
  std::size_t b = 0, before = 0;
  while (before + count[b] <= k) before += count[b++];
  std::size_t m = 0;
  for (std::size_t i = 0; i < n; ++i)
    if (bin(v[i]) == b) v[m++] = v[i];
  const std::size_t r = k - before;
  std::nth_element(v, v + r, v + m);
  return v[r];
}

}  // namespace scanclean::detail

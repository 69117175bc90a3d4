#pragma once
//! Internal: the parallel loops, progress reports, timers and small statistics the filter's
//! phases share. Every loop runs independent per-index work, so results do not depend on how
//! TBB splits a range or on the thread count.

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <string>
#include <type_traits>
#include <vector>

#include "huge_pages.h"
#include "radix_sort.h"
#include "scanclean/filter/filter_options.h"

namespace scanclean::detail {

using Clock = std::chrono::steady_clock;
inline double seconds_since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

constexpr std::size_t kGrain = 256;
//! "No index" in the filter's 32-bit index arrays.
constexpr std::uint32_t kNone = 0xffffffffu;

//! Runs f(i) for i in [0, n) in parallel.
template <class F>
void parallel_each(std::size_t n, F&& f) {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, kGrain),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i < r.end(); ++i) f(i);
                    });
}

//! from[order[k]] for each k, in parallel: values in another order (an index's slot order).
template <class T>
std::vector<T> permuted(const std::vector<T>& from, const std::vector<std::uint32_t>& order) {
  std::vector<T> to;
  resize_huge(to, order.size());
  parallel_each(order.size(), [&](std::size_t k) { to[k] = from[order[k]]; });
  return to;
}

//! As parallel_each, in sequential chunks, reporting progress from the calling thread.
template <class F>
void parallel_each_reporting(std::size_t n, const FilterOptions& o, const std::string& phase,
                             F&& f) {
  const std::size_t chunks =
      o.progress ? std::clamp<std::size_t>(n / 20000, 1, 50) : static_cast<std::size_t>(1);
  for (std::size_t c = 0; c < chunks; ++c) {
    const std::size_t b = n * c / chunks, e = n * (c + 1) / chunks;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(b, e, kGrain),
                      [&](const tbb::blocked_range<std::size_t>& r) {
                        for (std::size_t i = r.begin(); i < r.end(); ++i) f(i);
                      });
    if (o.progress) o.progress(phase, n ? static_cast<double>(e) / static_cast<double>(n) : 1.0);
  }
}

inline void report(const FilterOptions& o, const std::string& phase, double fraction) {
  if (o.progress) o.progress(phase, fraction);
}

//! How many i in [0, n) have pred(i), counted in parallel.
template <class Pred>
std::size_t count_where(std::size_t n, Pred&& pred) {
  return tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, n, 4096), std::size_t{0},
      [&](const tbb::blocked_range<std::size_t>& r, std::size_t c) {
        for (std::size_t i = r.begin(); i < r.end(); ++i) c += pred(i) ? 1 : 0;
        return c;
      },
      [](std::size_t a, std::size_t b) { return a + b; });
}

//! The smallest i in [0, n) with pred(i), or n if none, searched in parallel.
template <class Pred>
std::size_t first_where(std::size_t n, Pred&& pred) {
  return tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, n, 4096), n,
      [&](const tbb::blocked_range<std::size_t>& r, std::size_t first) {
        for (std::size_t i = r.begin(); i < r.end() && i < first; ++i)
          if (pred(i)) return i;
        return first;
      },
      [](std::size_t a, std::size_t b) { return std::min(a, b); });
}

//! The bounding box of the points (Eigen 3-vectors of float or double), in parallel (min and
//! max: the same box in any order).
template <class Vec>
Eigen::AlignedBox<typename Vec::Scalar, 3> bounding_box_of(const std::vector<Vec>& p) {
  using Box = Eigen::AlignedBox<typename Vec::Scalar, 3>;
  return tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, p.size(), 4096), Box(),
      [&](const tbb::blocked_range<std::size_t>& r, Box box) {
        for (std::size_t i = r.begin(); i < r.end(); ++i) box.extend(p[i]);
        return box;
      },
      [](const Box& a, const Box& b) { return a.merged(b); });
}

//! value(i) for the i in [0, n) with pred(i), in increasing i, found in parallel: counted chunk
//! by chunk, then written from each chunk's offset (pred is called twice per i). The same list
//! for any thread count.
template <class T, class Pred, class Value>
std::vector<T> values_where(std::size_t n, Pred&& pred, Value&& value) {
  constexpr std::size_t kChunk = std::size_t{1} << 15;
  const std::size_t chunks = std::clamp<std::size_t>(n / kChunk, 1, 256);
  auto chunk_begin = [&](std::size_t c) { return n * c / chunks; };
  std::vector<std::size_t> at(chunks + 1, 0);
  tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
    std::size_t m = 0;
    for (std::size_t i = chunk_begin(c); i < chunk_begin(c + 1); ++i) m += pred(i) ? 1 : 0;
    at[c + 1] = m;
  });
  for (std::size_t c = 0; c < chunks; ++c) at[c + 1] += at[c];
  std::vector<T> out;
  resize_huge(out, at[chunks]);
  tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
    std::size_t m = at[c];
    for (std::size_t i = chunk_begin(c); i < chunk_begin(c + 1); ++i)
      if (pred(i)) out[m++] = value(i);
  });
  return out;
}

//! The i in [0, n) with pred(i), in increasing order, found in parallel (values_where).
template <class Index = std::uint32_t, class Pred>
std::vector<Index> indices_where(std::size_t n, Pred&& pred) {
  return values_where<Index>(n, pred, [](std::size_t i) { return static_cast<Index>(i); });
}

//! The value of rank k (0-based, k < v.size()) in increasing order: the one std::nth_element
//! would put at k. v is read, not changed. Large arrays are narrowed in parallel, 11 bits of
//! the values' order keys a pass (a histogram per chunk: the bucket holding rank k keeps its
//! values, the others are counted), and the few thousand values left are selected by
//! std::nth_element; small ones are copied and selected. The k-th value is one number, so the
//! result does not depend on the chunks or the thread count. float or double; NaN not supported.
template <class T>
T radix_select(const std::vector<T>& v, std::size_t k) {
  static_assert(std::is_same_v<T, float> || std::is_same_v<T, double>);
  using Key = std::conditional_t<std::is_same_v<T, float>, std::uint32_t, std::uint64_t>;
  constexpr int kKeyBits = 8 * sizeof(Key);
  auto key = [](T x) -> Key {
    if constexpr (std::is_same_v<T, float>)
      return float_order_key(x);
    else
      return double_order_key(x);
  };
  const std::size_t n = v.size();
  constexpr std::size_t kFew = std::size_t{1} << 14;
  std::vector<T> left;
  if (n <= 4 * kFew) {
    left = v;
  } else {
    constexpr std::size_t kChunk = std::size_t{1} << 16;
    const std::size_t chunks = std::clamp<std::size_t>(n / kChunk, 1, 64);
    auto chunk_begin = [&](std::size_t c) { return n * c / chunks; };
    // The values whose key starts with `prefix` (its top `fixed` bits) are left; k is the rank
    // among them.
    Key prefix = 0;
    int fixed = 0;
    std::size_t count = n;
    auto kept = [&](Key u) { return fixed == 0 || (u >> (kKeyBits - fixed)) == prefix; };
    constexpr int kDigit = 11;
    constexpr std::size_t kBuckets = std::size_t{1} << kDigit;
    std::vector<std::size_t> hist(chunks * kBuckets);
    while (fixed < kKeyBits && count > kFew) {
      const int digit = std::min(kDigit, kKeyBits - fixed);
      const int shift = kKeyBits - fixed - digit;
      const Key mask = static_cast<Key>((Key{1} << digit) - 1);
      tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
        std::size_t* h = &hist[c * kBuckets];
        std::fill(h, h + kBuckets, 0);
        for (std::size_t i = chunk_begin(c); i < chunk_begin(c + 1); ++i) {
          const Key u = key(v[i]);
          if (kept(u)) ++h[(u >> shift) & mask];
        }
      });
      std::size_t below = 0, b = 0;
      for (;; ++b) {
        std::size_t in_b = 0;
        for (std::size_t c = 0; c < chunks; ++c) in_b += hist[c * kBuckets + b];
        if (k < below + in_b) {
          count = in_b;
          break;
        }
        below += in_b;
      }
      k -= below;
      prefix = static_cast<Key>((prefix << digit) | static_cast<Key>(b));
      fixed += digit;
    }
    // The values left, in index order (their order does not matter to the selection).
    left = values_where<T>(
        n, [&](std::size_t i) { return kept(key(v[i])); }, [&](std::size_t i) { return v[i]; });
  }
  const auto at_k = left.begin() + static_cast<std::ptrdiff_t>(k);
  std::nth_element(left.begin(), at_k, left.end());
  return *at_k;
}

//! The element at rank (n - 1) / 2 (the lower median); T{} for an empty vector. v is not
//! changed; float and double arrays are selected in parallel (radix_select).
template <class T>
T median_of(const std::vector<T>& v) {
  if (v.empty()) return T{};
  const std::size_t mid = (v.size() - 1) / 2;
  if constexpr (std::is_same_v<T, float> || std::is_same_v<T, double>) {
    return radix_select(v, mid);
  } else {
    std::vector<T> c = v;
    const auto at = c.begin() + static_cast<std::ptrdiff_t>(mid);
    std::nth_element(c.begin(), at, c.end());
    return *at;
  }
}

}  // namespace scanclean::detail

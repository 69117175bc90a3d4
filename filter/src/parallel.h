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
  std::vector<T> to(order.size());
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

//! The i in [0, n) with pred(i), in increasing order, found in parallel: counted chunk by chunk,
//! then written from each chunk's offset (pred is called twice per i). The same list for any
//! thread count.
template <class Index = std::uint32_t, class Pred>
std::vector<Index> indices_where(std::size_t n, Pred&& pred) {
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
  std::vector<Index> out(at[chunks]);
  tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
    std::size_t m = at[c];
    for (std::size_t i = chunk_begin(c); i < chunk_begin(c + 1); ++i)
      if (pred(i)) out[m++] = static_cast<Index>(i);
  });
  return out;
}

}  // namespace scanclean::detail

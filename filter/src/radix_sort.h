#pragma once
//! Internal: a stable least-significant-digit radix sort of records by an unsigned integer key,
//! 11 bits a pass over the bits the keys use. Stable: records with equal keys keep their order,
//! so a sort of records laid out in index order is a sort by (key, index).

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

namespace scanclean::detail {

//! Sorts v by key(record) (std::uint64_t), stably. `scratch` is resized and left unspecified.
//! Large arrays are counted and scattered in parallel, chunk by chunk (each chunk's records go
//! after those of the earlier chunks with the same digit): a stable sort has one result, so it
//! does not depend on the chunks or the thread count. Vec: a std::vector of the records, with
//! any allocator (FillLaterVector: the scratch is not zeroed before the first scatter).
template <class Vec, class Key>
void stable_radix_sort(Vec& v, Key&& key, Vec& scratch) {
  const std::size_t n = v.size();
  constexpr std::size_t kChunk = std::size_t{1} << 16;
  const std::size_t chunks = std::clamp<std::size_t>(n / kChunk, 1, 64);
  auto chunk_begin = [&](std::size_t c) { return n * c / chunks; };
  std::vector<std::uint64_t> used_by(chunks, 0);
  tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
    std::uint64_t u = 0;
    for (std::size_t i = chunk_begin(c); i < chunk_begin(c + 1); ++i) u |= key(v[i]);
    used_by[c] = u;
  });
  std::uint64_t used = 0;
  for (const std::uint64_t u : used_by) used |= u;
  int bits = 0;
  while (bits < 64 && (used >> bits) != 0) ++bits;
  if (bits == 0) return;
  constexpr int kDigit = 11;
  constexpr std::size_t kBuckets = std::size_t{1} << kDigit;
  scratch.resize(n);
  // Per chunk, per digit: the count, then where the chunk's first record with it goes.
  std::vector<std::size_t> at(chunks * kBuckets);
  for (int shift = 0; shift < bits; shift += kDigit) {
    tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
      std::size_t* count = &at[c * kBuckets];
      std::fill(count, count + kBuckets, 0);
      for (std::size_t i = chunk_begin(c); i < chunk_begin(c + 1); ++i)
        ++count[(key(v[i]) >> shift) & (kBuckets - 1)];
    });
    std::size_t sum = 0;
    for (std::size_t b = 0; b < kBuckets; ++b)
      for (std::size_t c = 0; c < chunks; ++c) sum += std::exchange(at[c * kBuckets + b], sum);
    tbb::parallel_for(std::size_t{0}, chunks, [&](std::size_t c) {
      std::size_t* next = &at[c * kBuckets];
      for (std::size_t i = chunk_begin(c); i < chunk_begin(c + 1); ++i)
        scratch[next[(key(v[i]) >> shift) & (kBuckets - 1)]++] = v[i];
    });
    v.swap(scratch);
  }
}

//! An unsigned key with the order of the float f (-0 and +0 equal; NaN not supported).
inline std::uint32_t float_order_key(float f) {
  if (f == 0) f = 0;  // -0 as +0: equal under <, so equal keys
  std::uint32_t u;
  static_assert(sizeof u == sizeof f);
  __builtin_memcpy(&u, &f, sizeof u);
  return (u >> 31) != 0 ? ~u : u | 0x80000000u;
}

//! An unsigned key with the order of the double d (-0 and +0 equal; NaN not supported).
inline std::uint64_t double_order_key(double d) {
  if (d == 0) d = 0;
  std::uint64_t u;
  static_assert(sizeof u == sizeof d);
  __builtin_memcpy(&u, &d, sizeof u);
  return (u >> 63) != 0 ? ~u : u | (std::uint64_t{1} << 63);
}

}  // namespace scanclean::detail

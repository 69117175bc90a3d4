#pragma once
//! Internal: a stable least-significant-digit radix sort of records by an unsigned integer key,
//! 11 bits a pass over the bits the keys use. Stable: records with equal keys keep their order,
//! so a sort of records laid out in index order is a sort by (key, index).

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

namespace scanclean::detail {

//! Sorts v by key(record) (std::uint64_t), stably. `scratch` is resized and left unspecified.
template <class T, class Key>
void stable_radix_sort(std::vector<T>& v, Key&& key, std::vector<T>& scratch) {
  std::uint64_t used = 0;
  for (const T& e : v) used |= key(e);
  int bits = 0;
  while (bits < 64 && (used >> bits) != 0) ++bits;
  if (bits == 0) return;
  constexpr int kDigit = 11;
  constexpr std::size_t kBuckets = std::size_t{1} << kDigit;
  scratch.resize(v.size());
  std::vector<std::size_t> count(kBuckets);
  for (int shift = 0; shift < bits; shift += kDigit) {
    std::fill(count.begin(), count.end(), 0);
    for (const T& e : v) ++count[(key(e) >> shift) & (kBuckets - 1)];
    std::size_t sum = 0;
    for (std::size_t& c : count) sum += std::exchange(c, sum);
    for (const T& e : v) scratch[count[(key(e) >> shift) & (kBuckets - 1)]++] = e;
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

}  // namespace scanclean::detail

#pragma once
//! Internal: the building blocks of the 8-wide (AVX2) selections by distance, shared by the
//! candidate selection (candidate_eval.cpp) and the band and within counts (select.cpp): the
//! squared distances of 8 points, rounded as the scalar loops round them, and left-packing of the
//! selected lanes (_mm256_permutevar8x32 with a lane table).

#include <immintrin.h>

#include <cstddef>
#include <cstdint>

namespace scanclean::detail {

//! For each 8-bit mask of selected lanes, the indices of its set bits in increasing order, then
//! zeros.
struct LeftPackTable {
  std::int32_t lane[256][8];
  constexpr LeftPackTable() : lane{} {
    for (int mask = 0; mask < 256; ++mask) {
      int k = 0;
      for (int bit = 0; bit < 8; ++bit)
        if (mask & (1 << bit)) lane[mask][k++] = bit;
    }
  }
};
inline constexpr LeftPackTable kLeftPack;

// The helpers take and return vectors by value; they are always inlined into functions compiled
// for AVX2, so the ABI note GCC gives for them does not apply.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"

//! |p_j - q|^2 of the 8 points (x[j], y[j], z[j]), j < 8, rounded as a plain scalar loop
//! computes it: (dx dx + dy dy) + dz dz in float, without fused multiply-add.
[[gnu::target("avx2"), gnu::always_inline]] inline __m256 squared_distances8(
    const float* x, const float* y, const float* z, __m256 qx, __m256 qy, __m256 qz) {
  const __m256 dx = _mm256_sub_ps(_mm256_loadu_ps(x), qx);
  const __m256 dy = _mm256_sub_ps(_mm256_loadu_ps(y), qy);
  const __m256 dz = _mm256_sub_ps(_mm256_loadu_ps(z), qz);
  return _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(dx, dx), _mm256_mul_ps(dy, dy)),
                       _mm256_mul_ps(dz, dz));
}

//! The lanes below `left` (1 to 8) as a mask: a last partial block of points.
[[gnu::target("avx2"), gnu::always_inline]] inline __m256i lanes_below(std::size_t left) {
  return _mm256_cmpgt_epi32(_mm256_set1_epi32(static_cast<int>(left)),
                            _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
}
//! squared_distances8 for the lanes of `in` (lanes_below), which reads nothing past them (the
//! other lanes hold |q|^2 and are for the caller to drop).
[[gnu::target("avx2"), gnu::always_inline]] inline __m256 squared_distances8_masked(
    const float* x, const float* y, const float* z, __m256 qx, __m256 qy, __m256 qz, __m256i in) {
  const __m256 dx = _mm256_sub_ps(_mm256_maskload_ps(x, in), qx);
  const __m256 dy = _mm256_sub_ps(_mm256_maskload_ps(y, in), qy);
  const __m256 dz = _mm256_sub_ps(_mm256_maskload_ps(z, in), qz);
  return _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(dx, dx), _mm256_mul_ps(dy, dy)),
                       _mm256_mul_ps(dz, dz));
}

//! Stores the 8 values v[0, 8) at out with the lanes selected by mask first, in order; all 8 are
//! stored (out needs room for 8). Returns the number selected.
[[gnu::target("avx2"), gnu::always_inline]] inline std::size_t store_left_packed(
    std::uint32_t* out, const std::uint32_t* v, unsigned mask) {
  const __m256i perm = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(kLeftPack.lane[mask]));
  const __m256i s = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(v));
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(out), _mm256_permutevar8x32_epi32(s, perm));
  return static_cast<std::size_t>(__builtin_popcount(mask));
}
//! As above for the 8 integers of a vector.
[[gnu::target("avx2"), gnu::always_inline]] inline std::size_t store_left_packed(std::uint32_t* out,
                                                                                 __m256i v,
                                                                                 unsigned mask) {
  const __m256i perm = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(kLeftPack.lane[mask]));
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(out), _mm256_permutevar8x32_epi32(v, perm));
  return static_cast<std::size_t>(__builtin_popcount(mask));
}
//! As above for the 8 floats of a vector.
[[gnu::target("avx2"), gnu::always_inline]] inline std::size_t store_left_packed(float* out,
                                                                                 __m256 v,
                                                                                 unsigned mask) {
  const __m256i perm = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(kLeftPack.lane[mask]));
  _mm256_storeu_ps(out, _mm256_permutevar8x32_ps(v, perm));
  return static_cast<std::size_t>(__builtin_popcount(mask));
}

#pragma GCC diagnostic pop

}  // namespace scanclean::detail

#pragma once
//! Internal: the lane table of 8-wide left-packing (AVX2 _mm256_permutevar8x32): for each 8-bit
//! mask of selected lanes, the indices of its set bits in increasing order, then zeros. Used by
//! the candidate selection (candidate_eval.cpp) and the band counts (select.cpp).

#include <cstdint>

namespace scanclean::detail {

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

}  // namespace scanclean::detail

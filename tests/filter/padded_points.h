#pragma once
// Test input for the selections by distance (filter/src/select.h), which take their points
// padded to a multiple of 8.

#include <cstdint>
#include <limits>
#include <vector>

namespace scanclean::test {

// Pads the points with +inf coordinates (never selected) to a multiple of 8, as the selections
// ask; slots (and sigma, when given) get `slot` (and `s`) there.
inline void pad_at_infinity(std::vector<float>& x, std::vector<float>& y, std::vector<float>& z,
                            std::vector<std::uint32_t>& slots, std::uint32_t slot,
                            std::vector<float>* sigma = nullptr, float s = 0) {
  const float inf = std::numeric_limits<float>::infinity();
  while (x.size() % 8 != 0) {
    x.push_back(inf);
    y.push_back(inf);
    z.push_back(inf);
    slots.push_back(slot);
    if (sigma) sigma->push_back(s);
  }
}

}  // namespace scanclean::test

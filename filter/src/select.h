#pragma once
//! Internal: selection of the k-th smallest value, exact and faster than std::nth_element when
//! the values are known to lie in a range [0, upper).

#include <cstddef>

namespace scanclean::detail {

//! The k-th smallest (0-based rank) of v[0, n), k < n, every value in [0, upper): the value
//! std::nth_element would put at v[k]. Sorts the values into 64 equal bins of [0, upper) (a
//! monotone map, so a bin's values lie between its neighbours'), then selects within the one bin
//! that holds rank k. Overwrites v (scratch). Falls back to std::nth_element for n <= 64 or
//! upper <= 0; values outside [0, upper) go to the end bins, which keeps the result exact.
float kth_smallest_below(float* v, std::size_t n, std::size_t k, float upper);

}  // namespace scanclean::detail

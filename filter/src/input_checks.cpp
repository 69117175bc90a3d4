#include "input_checks.h"

#include <sstream>

#include "parallel.h"

namespace scanclean::detail {

InvalidPoint first_invalid_point(const PointCloud& c, bool weights) {
  const std::size_t n = c.size();
  // The first offending point, found in parallel.
  const std::size_t bad_position =
      first_where(n, [&](std::size_t i) { return !c.positions[i].allFinite(); });
  if (bad_position < n)
    return {bad_position, "non-finite coordinate (remove invalid points before filtering)"};
  if (weights) {
    const std::size_t i = first_where(
        n, [&](std::size_t k) { return !(c.confidences[k] >= 0.0f && c.confidences[k] <= 1.0f); });
    if (i < n) {
      std::ostringstream v;
      v << c.confidences[i];
      return {i, "confidence " + v.str() + " outside [0, 1]"};
    }
  }
  return {n, {}};
}

}  // namespace scanclean::detail

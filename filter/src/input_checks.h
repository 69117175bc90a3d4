// The checks robust_filter makes of its input points, shared with the tiled filter's first pass.
#pragma once

#include <cstddef>
#include <string>

#include "scanclean/core/point_cloud.h"

namespace scanclean::detail {

//! The first point the filter refuses: a non-finite position first, then, when `weights`, a
//! confidence outside [0, 1]. `index` is c.size() when there is none; `what` says why.
struct InvalidPoint {
  std::size_t index = 0;
  std::string what;
};
InvalidPoint first_invalid_point(const PointCloud& c, bool weights);

}  // namespace scanclean::detail

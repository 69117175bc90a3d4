#include "position_precision.h"

#include <cmath>
#include <limits>

#include <Eigen/Geometry>

namespace scanclean::io_detail {

bool positions_fit_float(const std::vector<Eigen::Vector3d>& positions) {
  Eigen::AlignedBox3d box;
  for (const auto& p : positions)
    if (p.allFinite()) box.extend(p);
  if (box.isEmpty()) return true;
  const double tolerance = 1e-6 * box.diagonal().norm();
  constexpr double kFloatMax = static_cast<double>(std::numeric_limits<float>::max());
  for (const auto& p : positions)
    for (int k = 0; k < 3; ++k) {
      const double v = p[k];
      if (!std::isfinite(v)) continue;
      if (std::abs(v) > kFloatMax) return false;
      if (std::abs(static_cast<double>(static_cast<float>(v)) - v) > tolerance) return false;
    }
  return true;
}

}  // namespace scanclean::io_detail

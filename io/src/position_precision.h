#pragma once
// Internal: whether positions can be stored as float without losing precision that matters.

#include <vector>

#include <Eigen/Core>

namespace scanclean::io_detail {

//! True when every coordinate, converted to float, stays within 1e-6 of the bounding-box diagonal
//! of its double value (always true for data read from float files). Else writers use double.
bool positions_fit_float(const std::vector<Eigen::Vector3d>& positions);

}  // namespace scanclean::io_detail

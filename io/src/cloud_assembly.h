#pragma once
// Internal: turns named per-point columns (as read from PLY/PCD) into a PointCloud, mapping the
// conventional names to the PointCloud arrays and keeping the rest as attributes.

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "scanclean/core/point_cloud.h"
#include "scanclean/io/io_types.h"

namespace scanclean::io_detail {

struct Column {
  std::string name;
  AttributeType type = AttributeType::kFloat32;  //!< storage type if kept as an attribute
  bool floating = false;  //!< source values are floating point (colours in [0,1] then)
  std::vector<double> values;
};

//! A colour channel as a byte: integers as they are, floats (floating) in [0, 1] scaled by 255;
//! rounded and clamped to [0, 255]; NaN is 0. Used by every reader.
std::uint8_t to_colour_byte(double v, bool floating);

enum class InvalidPolicy { kDrop, kReject };

//! Builds the cloud. Names: x y z (required); nx ny nz or normal_x normal_y normal_z; confidence;
//! intensity; red green blue [alpha] or diffuse_red ... (integers 0..255, or floats in [0,1]);
//! every other column becomes an Attribute. Points with a non-finite x, y or z are dropped
//! (kDrop: counted in report->dropped_invalid and a warning; grid cells become -1) or rejected
//! (kReject: InputError naming the point via place_of(index)).
PointCloud assemble_cloud(std::vector<Column>& columns, std::size_t n, OrganizedGrid grid,
                          const std::string& file, const std::string& element_word,
                          InvalidPolicy policy, ReadReport* report,
                          const std::function<std::string(std::size_t)>& place_of);

}  // namespace scanclean::io_detail

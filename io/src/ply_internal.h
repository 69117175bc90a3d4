#pragma once
// Internal: the PLY reader shared by read_ply and read_triangle_mesh.

#include <array>
#include <filesystem>
#include <vector>

#include "scanclean/core/point_cloud.h"
#include "scanclean/io/io_types.h"

namespace scanclean::io_detail {

struct PlyContent {
  PointCloud cloud;
  std::vector<std::array<int, 3>> triangles;  //!< filled only when faces were requested
};

//! mesh = true: read the face element into triangles, reject non-finite vertices, ignore the
//! range grid. mesh = false: point cloud (faces skipped, range_grid used, non-finite dropped).
PlyContent read_ply_content(const std::filesystem::path& path, ReadReport* report, bool mesh);

}  // namespace scanclean::io_detail

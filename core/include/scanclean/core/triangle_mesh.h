#pragma once
//! \file triangle_mesh.h
//! An indexed triangle mesh (e.g. a ground-truth reconstruction such as Stanford's bun_zipper.ply).
//! Units: metres, like PointCloud. Header-only.

#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <vector>

namespace scanclean {

struct TriangleMesh {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<std::array<int, 3>> triangles;  //!< indices into vertices, each in [0, size)

  std::size_t vertex_count() const { return vertices.size(); }
  std::size_t triangle_count() const { return triangles.size(); }
};

}  // namespace scanclean

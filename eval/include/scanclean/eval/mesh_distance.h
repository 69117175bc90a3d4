#pragma once
//! \file mesh_distance.h
//! Exact unsigned point-to-mesh distance: the closest point over all triangles, found through a
//! bounding-volume hierarchy over the triangles (median split, 4 triangles per leaf) with
//! nearest-first branch-and-bound traversal. Units: those of the mesh (metres here).

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "scanclean/core/triangle_mesh.h"

namespace scanclean {

//! Closest point on the triangle (a, b, c) to p (exact; degenerate triangles handled as their
//! edges/points).
Eigen::Vector3d closest_point_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                          const Eigen::Vector3d& b, const Eigen::Vector3d& c);

class MeshDistance {
 public:
  struct Hit {
    Eigen::Vector3d point;     //!< closest point on the mesh
    double distance = 0;       //!< |p - point|
    std::size_t triangle = 0;  //!< index into the mesh's triangles
  };

  //! Builds the hierarchy (O(T log T)). The mesh is copied; it must have at least one triangle
  //! and valid indices. \throw InputError for an empty mesh or an index out of range.
  explicit MeshDistance(const TriangleMesh& mesh);

  //! Distance from p to the closest point of the mesh. Thread-safe (const, no shared state).
  double distance(const Eigen::Vector3d& p) const { return query(p).distance; }
  //! The closest point of the mesh to p. Thread-safe.
  Eigen::Vector3d closest_point(const Eigen::Vector3d& p) const { return query(p).point; }
  //! Closest point, distance and triangle. Thread-safe.
  Hit query(const Eigen::Vector3d& p) const;

  std::size_t triangle_count() const { return tri_a_.size(); }

 private:
  struct Node {
    Eigen::Vector3d lo = Eigen::Vector3d::Zero(), hi = Eigen::Vector3d::Zero();
    std::uint32_t left = 0, right = 0;  //!< inner node: children
    std::uint32_t first = 0;            //!< leaf: first triangle slot
    std::uint32_t count = 0;            //!< leaf: number of triangles (> 0); inner: 0
  };
  std::uint32_t build(std::uint32_t begin, std::uint32_t end,
                      std::vector<Eigen::Vector3d>& centroids);

  std::vector<Eigen::Vector3d> tri_a_, tri_b_, tri_c_;  //!< triangle corners in BVH leaf order
  std::vector<std::size_t> tri_index_;                  //!< original triangle index per slot
  std::vector<Node> nodes_;
};

}  // namespace scanclean

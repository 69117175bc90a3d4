#pragma once
// Private to the mesh module: the CGAL calls behind plain types (one algorithm per translation
// unit, so that CGAL's heavy headers are compiled once each).

#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <vector>

#include "scanclean/core/triangle_mesh.h"

namespace scanclean::mesh_detail {

//! CGAL::advancing_front_surface_reconstruction; triangles index `points`. max_edge <= 0: none.
std::vector<std::array<int, 3>> advancing_front(const std::vector<Eigen::Vector3d>& points,
                                                double max_edge, double radius_ratio_bound,
                                                double beta);

//! CGAL Poisson reconstruction + surface mesher (Epick). Empty mesh when the solver fails.
TriangleMesh poisson(const std::vector<Eigen::Vector3d>& points,
                     const std::vector<Eigen::Vector3f>& normals, double spacing, double angle,
                     double radius, double distance);

//! CGAL::compute_average_spacing (parallel).
double average_spacing(const std::vector<Eigen::Vector3d>& points, int k);

//! CGAL::jet_estimate_normals (parallel), unoriented.
std::vector<Eigen::Vector3f> jet_normals(const std::vector<Eigen::Vector3d>& points, int k);

//! CGAL::pca_estimate_normals (parallel), unoriented.
std::vector<Eigen::Vector3f> pca_normals(const std::vector<Eigen::Vector3d>& points, int k);

//! CGAL::mst_orient_normals in place; returns how many normals were flipped. Points it could
//! not reach keep their normal.
std::size_t mst_orient(const std::vector<Eigen::Vector3d>& points,
                       std::vector<Eigen::Vector3f>& normals, int k);

//! Share of (point, k-nearest neighbour) pairs whose normals have a positive dot product.
double normal_agreement(const std::vector<Eigen::Vector3d>& points,
                        const std::vector<Eigen::Vector3f>& normals, int k);

}  // namespace scanclean::mesh_detail

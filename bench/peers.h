#pragma once
//! \file peers.h
//! The methods the benchmark compares scanclean's robust_filter with. CGAL stays inside the
//! peer_cgal_*.cpp files (one translation unit each); only Eigen types cross this header.
//! All CGAL calls use CGAL::Parallel_if_available_tag (TBB is linked, so they run in parallel
//! under the caller's tbb::global_control limit).

#include <Eigen/Core>
#include <cstdint>
#include <vector>

namespace scanclean::bench {

using Points = std::vector<Eigen::Vector3d>;

//! CGAL::jet_smooth_point_set with k neighbours, degree_fitting = degree_monge = 2 (defaults).
Points cgal_jet_smooth(const Points& in, unsigned k);
//! CGAL::pca_estimate_normals (k neighbours, unoriented) followed by `iterations` calls of
//! CGAL::bilateral_smooth_point_set(k, sharpness_angle), as in CGAL's documented example.
Points cgal_bilateral_smooth(const Points& in, unsigned k, double sharpness_angle, int iterations);
//! CGAL::wlop_simplify_and_regularize_point_set. neighbor_radius <= 0 keeps CGAL's default
//! (8 x the average spacing over 6 neighbours).
Points cgal_wlop(const Points& in, double select_percentage, double neighbor_radius,
                 unsigned iterations);
//! CGAL::remove_outliers (k neighbours; threshold_percent, threshold_distance as documented).
//! Returns one flag per input point: 1 = kept.
std::vector<std::uint8_t> cgal_remove_outliers(const Points& in, unsigned k,
                                               double threshold_percent, double threshold_distance);
//! CGAL::compute_average_spacing over k neighbours.
double cgal_average_spacing(const Points& in, unsigned k);

//! Our plain baseline: each point projected onto the least-squares plane (PCA) of its k nearest
//! neighbours (itself included). Parallel, deterministic.
Points pca_plane_projection(const Points& in, int k);
//! Statistical outlier removal as PCL (StatisticalOutlierRemoval) and Open3D
//! (remove_statistical_outlier) define it: d_i = mean distance to the k nearest neighbours
//! (itself excluded); keep i if d_i <= mean(d) + std_ratio * std(d) (sample standard deviation).
//! Returns one flag per input point: 1 = kept.
std::vector<std::uint8_t> statistical_outlier_removal(const Points& in, int k, double std_ratio);

}  // namespace scanclean::bench

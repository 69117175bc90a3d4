#pragma once
//! Internal: consistently oriented normals for a cloud that has none (FilterOptions::orient_k),
//! so that the kernels' orientation test (kernel_fit.h) applies to it as to sensor data: the two
//! sides of a thin part, once their normals face away from each other, no longer fit into one
//! kernel. The recipe of Hoppe et al. (1992) and CGAL's pca_estimate_normals +
//! mst_orient_normals: each point's PCA normal over its k nearest neighbours, the graph of its
//! kOrientationGraphNeighbours nearest (filter_options.h) weighted 1 - |n_i . n_j|, and the normals
//! turned along the graph's minimum spanning forest, each tree's highest point facing up (+z). The
//! forest comes from Kruskal's algorithm over the edges sorted once, with a union-find that keeps
//! each point's parity (turned or not) against its root.

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include "scanclean/filter/filter_options.h"

namespace scanclean::detail {

//! An edge of the neighbour graph: a < b, its weight 1 - |n_a . n_b| and whether the two
//! normals, as they are, face opposite ways (n_a . n_b < 0).
struct OrientationEdge {
  float weight = 0;
  std::uint32_t a = 0, b = 0;
  bool opposite = false;
};

//! Per node of a graph of n nodes: whether its normal turns (1) or not (0) so that the edges of
//! the minimum spanning forest all join agreeing normals; each tree's smallest node keeps its
//! own. The forest is Kruskal's over `edges` ordered by (weight, a, b), so it is unique.
//! `edges` is sorted in place. Deterministic.
struct SpanningForest {
  std::vector<std::uint8_t> turn;   //!< per node
  std::vector<std::uint32_t> tree;  //!< per node: the smallest node of its tree
  std::size_t trees = 0;            //!< trees with at least one edge
  double weight = 0;                //!< sum of the forest's edge weights
};
SpanningForest orient_along_spanning_forest(std::size_t n, std::vector<OrientationEdge>& edges);

struct OrientedPointNormals {
  std::vector<Eigen::Vector3f> normals;  //!< per point: unit
  std::size_t trees = 0;                 //!< connected pieces of the neighbour graph
};

//! Oriented normals for the points `p` (metres, any local frame): PCA over each point's k
//! nearest (itself included), oriented along the spanning forest of the graph of the
//! kOrientationGraphNeighbours nearest; or, given a `viewpoint` (in p's frame), each turned to
//! face it (no graph; trees = 0). Parallel, and the same for any thread count.
OrientedPointNormals orient_normals(const std::vector<Eigen::Vector3f>& p, int k,
                                    const FilterOptions& o,
                                    const std::optional<Eigen::Vector3f>& viewpoint = {});

}  // namespace scanclean::detail

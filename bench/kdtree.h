#pragma once
//! \file kdtree.h
//! Nearest-neighbour queries over a fixed point array (nanoflann), for the benchmark's metrics and
//! its own baselines (PCA projection, statistical outlier removal). Bench-only helper.

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

namespace scanclean::bench {

//! A k-d tree over `points` (which must outlive it and stay unchanged). Const queries are
//! thread-safe.
class KdTree {
 public:
  explicit KdTree(const std::vector<Eigen::Vector3d>& points);
  ~KdTree();
  KdTree(const KdTree&) = delete;
  KdTree& operator=(const KdTree&) = delete;

  //! Index and squared distance of the nearest point. Precondition: the tree is not empty.
  std::pair<std::uint32_t, double> nearest(const Eigen::Vector3d& q) const;
  //! The k nearest points (sorted by distance; fewer if the tree holds fewer), as indices and
  //! squared distances (both resized to the count found).
  void knn(const Eigen::Vector3d& q, std::size_t k, std::vector<std::uint32_t>& indices,
           std::vector<double>& sq_dists) const;
  std::size_t size() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace scanclean::bench

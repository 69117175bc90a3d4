#include "kdtree.h"

#include <nanoflann.hpp>

namespace scanclean::bench {

namespace {
struct Adaptor {
  const std::vector<Eigen::Vector3d>* pts;
  std::size_t kdtree_get_point_count() const { return pts->size(); }
  double kdtree_get_pt(std::size_t i, std::size_t d) const {
    return (*pts)[i][static_cast<int>(d)];
  }
  template <class Box>
  bool kdtree_get_bbox(Box&) const {
    return false;
  }
};
using Tree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, Adaptor>,
                                                 Adaptor, 3, std::uint32_t>;
}  // namespace

struct KdTree::Impl {
  Adaptor adaptor;
  Tree tree;
  explicit Impl(const std::vector<Eigen::Vector3d>& p)
      : adaptor{&p}, tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(12)) {
    tree.buildIndex();
  }
};

KdTree::KdTree(const std::vector<Eigen::Vector3d>& points)
    : impl_(std::make_unique<Impl>(points)) {}
KdTree::~KdTree() = default;

std::size_t KdTree::size() const {
  return impl_->adaptor.pts->size();
}

std::pair<std::uint32_t, double> KdTree::nearest(const Eigen::Vector3d& q) const {
  std::uint32_t index = 0;
  double d2 = 0;
  nanoflann::KNNResultSet<double, std::uint32_t> result(1);
  result.init(&index, &d2);
  impl_->tree.findNeighbors(result, q.data(), nanoflann::SearchParams());
  return {index, d2};
}

void KdTree::knn(const Eigen::Vector3d& q, std::size_t k, std::vector<std::uint32_t>& indices,
                 std::vector<double>& sq_dists) const {
  indices.resize(k);
  sq_dists.resize(k);
  nanoflann::KNNResultSet<double, std::uint32_t> result(k);
  result.init(indices.data(), sq_dists.data());
  impl_->tree.findNeighbors(result, q.data(), nanoflann::SearchParams());
  indices.resize(result.size());
  sq_dists.resize(result.size());
}

}  // namespace scanclean::bench

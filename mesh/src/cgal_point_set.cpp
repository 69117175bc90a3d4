// CGAL point-set processing for meshing: average spacing, jet and PCA normals, MST
// orientation; and the normal-agreement check (nanoflann).
#include <CGAL/Simple_cartesian.h>
#include <CGAL/compute_average_spacing.h>
#include <CGAL/jet_estimate_normals.h>
#include <CGAL/mst_orient_normals.h>
#include <CGAL/pca_estimate_normals.h>
#include <CGAL/property_map.h>
#include <CGAL/tags.h>

#include <nanoflann.hpp>
#include <tuple>

#include "cgal_reconstruction.h"

namespace scanclean::mesh_detail {
namespace {

using Kernel = CGAL::Simple_cartesian<double>;
using Point = Kernel::Point_3;
using Vector = Kernel::Vector_3;
using Concurrency = CGAL::Parallel_if_available_tag;

std::vector<Point> to_cgal(const std::vector<Eigen::Vector3d>& in) {
  std::vector<Point> out;
  out.reserve(in.size());
  for (const auto& p : in) out.emplace_back(p.x(), p.y(), p.z());
  return out;
}

struct CloudAdaptor {
  const std::vector<Eigen::Vector3d>* pts;
  std::size_t kdtree_get_point_count() const { return pts->size(); }
  double kdtree_get_pt(std::size_t i, std::size_t d) const {
    return (*pts)[i][static_cast<Eigen::Index>(d)];
  }
  template <class Box>
  bool kdtree_get_bbox(Box&) const {
    return false;
  }
};

}  // namespace

double average_spacing(const std::vector<Eigen::Vector3d>& points, int k) {
  const std::vector<Point> pts = to_cgal(points);
  return CGAL::compute_average_spacing<Concurrency>(pts, static_cast<unsigned>(k));
}

namespace {

// CGAL's jet or PCA normal estimation over k neighbours (unoriented), as floats.
template <bool kJet>
std::vector<Eigen::Vector3f> cgal_normals(const std::vector<Eigen::Vector3d>& points, int k) {
  using PointWithNormal = std::pair<Point, Vector>;
  std::vector<PointWithNormal> pwn;
  pwn.reserve(points.size());
  for (const auto& p : points) pwn.emplace_back(Point(p.x(), p.y(), p.z()), Vector(0, 0, 0));
  const auto params =
      CGAL::parameters::point_map(CGAL::First_of_pair_property_map<PointWithNormal>())
          .normal_map(CGAL::Second_of_pair_property_map<PointWithNormal>());
  if constexpr (kJet)
    CGAL::jet_estimate_normals<Concurrency>(pwn, static_cast<unsigned>(k), params);
  else
    CGAL::pca_estimate_normals<Concurrency>(pwn, static_cast<unsigned>(k), params);
  std::vector<Eigen::Vector3f> out;
  out.reserve(pwn.size());
  for (const auto& [p, n] : pwn)
    out.emplace_back(static_cast<float>(n.x()), static_cast<float>(n.y()),
                     static_cast<float>(n.z()));
  return out;
}

}  // namespace

std::vector<Eigen::Vector3f> jet_normals(const std::vector<Eigen::Vector3d>& points, int k) {
  return cgal_normals<true>(points, k);
}

std::vector<Eigen::Vector3f> pca_normals(const std::vector<Eigen::Vector3d>& points, int k) {
  return cgal_normals<false>(points, k);
}

std::size_t mst_orient(const std::vector<Eigen::Vector3d>& points,
                       std::vector<Eigen::Vector3f>& normals, int k) {
  using Row = std::tuple<Point, Vector, std::size_t>;
  std::vector<Row> rows;
  rows.reserve(points.size());
  for (std::size_t i = 0; i < points.size(); ++i)
    rows.emplace_back(Point(points[i].x(), points[i].y(), points[i].z()),
                      Vector(normals[i].x(), normals[i].y(), normals[i].z()), i);
  const auto unoriented = CGAL::mst_orient_normals(
      rows, static_cast<unsigned>(k),
      CGAL::parameters::point_map(CGAL::Nth_of_tuple_property_map<0, Row>())
          .normal_map(CGAL::Nth_of_tuple_property_map<1, Row>()));
  std::size_t flipped = 0;
  for (auto it = rows.begin(); it != unoriented; ++it) {
    const std::size_t i = std::get<2>(*it);
    const Vector& n = std::get<1>(*it);
    const Eigen::Vector3f v(static_cast<float>(n.x()), static_cast<float>(n.y()),
                            static_cast<float>(n.z()));
    if (v.dot(normals[i]) < 0) ++flipped;
    normals[i] = v;
  }
  return flipped;
}

double normal_agreement(const std::vector<Eigen::Vector3d>& points,
                        const std::vector<Eigen::Vector3f>& normals, int k) {
  using Tree =
      nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, CloudAdaptor>,
                                          CloudAdaptor, 3, std::size_t>;
  CloudAdaptor adaptor{&points};
  Tree tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(16));
  tree.buildIndex();
  const std::size_t kk = std::min<std::size_t>(static_cast<std::size_t>(k) + 1, points.size());
  std::vector<std::size_t> idx(kk);
  std::vector<double> d2(kk);
  std::size_t pairs = 0, agree = 0;
  // Every 4th point is enough for a share.
  for (std::size_t i = 0; i < points.size(); i += 4) {
    const std::size_t found = tree.knnSearch(points[i].data(), kk, idx.data(), d2.data());
    for (std::size_t j = 0; j < found; ++j) {
      if (idx[j] == i) continue;
      ++pairs;
      if (normals[i].dot(normals[idx[j]]) > 0) ++agree;
    }
  }
  return pairs == 0 ? 1.0 : static_cast<double>(agree) / static_cast<double>(pairs);
}

}  // namespace scanclean::mesh_detail

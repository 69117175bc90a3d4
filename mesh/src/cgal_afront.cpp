// CGAL advancing-front surface reconstruction with an edge-length limit.
#include <CGAL/Advancing_front_surface_reconstruction.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

#include <limits>

#include "cgal_reconstruction.h"

namespace scanclean::mesh_detail {
namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = Kernel::Point_3;

// CGAL's default priority (the smallest Delaunay ball's radius), with infinity (CGAL's "never a
// candidate") for a triangle that has an edge longer than the limit.
struct EdgeLimitPriority {
  double max_edge2 = 0;  // squared; <= 0: no limit
  template <class Reconstruction>
  double operator()(const Reconstruction& r, const typename Reconstruction::Cell_handle& c,
                    const int& index) const {
    if (max_edge2 > 0) {
      for (int i = 0; i < 4; ++i) {
        if (i == index) continue;
        for (int j = i + 1; j < 4; ++j) {
          if (j == index) continue;
          if (CGAL::squared_distance(c->vertex(i)->point(), c->vertex(j)->point()) > max_edge2)
            return std::numeric_limits<double>::infinity();
        }
      }
    }
    return r.smallest_radius_delaunay_sphere(c, index);
  }
};

}  // namespace

std::vector<std::array<int, 3>> advancing_front(const std::vector<Eigen::Vector3d>& points,
                                                double max_edge, double radius_ratio_bound,
                                                double beta) {
  std::vector<Point> pts;
  pts.reserve(points.size());
  for (const auto& p : points) pts.emplace_back(p.x(), p.y(), p.z());
  std::vector<std::array<std::size_t, 3>> facets;
  EdgeLimitPriority priority;
  priority.max_edge2 = max_edge > 0 ? max_edge * max_edge : 0.0;
  CGAL::advancing_front_surface_reconstruction(pts.begin(), pts.end(), std::back_inserter(facets),
                                               priority, radius_ratio_bound, beta);
  std::vector<std::array<int, 3>> out;
  out.reserve(facets.size());
  for (const auto& f : facets)
    out.push_back({static_cast<int>(f[0]), static_cast<int>(f[1]), static_cast<int>(f[2])});
  return out;
}

}  // namespace scanclean::mesh_detail

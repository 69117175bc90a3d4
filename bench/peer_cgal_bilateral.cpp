#include <CGAL/bilateral_smooth_point_set.h>
#include <CGAL/pca_estimate_normals.h>
#include <CGAL/property_map.h>

#include <utility>

#include "peer_cgal_common.h"

namespace scanclean::bench {

Points cgal_bilateral_smooth(const Points& in, unsigned k, double sharpness_angle, int iterations) {
  using namespace cgal_peer;
  using PointNormal = std::pair<Point, Vector>;
  std::vector<PointNormal> pts;
  pts.reserve(in.size());
  for (const auto& p : in) pts.emplace_back(Point(p.x(), p.y(), p.z()), Vector(0, 0, 0));
  const auto np = CGAL::parameters::point_map(CGAL::First_of_pair_property_map<PointNormal>())
                      .normal_map(CGAL::Second_of_pair_property_map<PointNormal>());
  CGAL::pca_estimate_normals<Concurrency>(pts, k, np);
  for (int i = 0; i < iterations; ++i)
    CGAL::bilateral_smooth_point_set<Concurrency>(pts, k, np.sharpness_angle(sharpness_angle));
  Points out;
  out.reserve(pts.size());
  for (const auto& p : pts) out.push_back(to_eigen(p.first));
  return out;
}

}  // namespace scanclean::bench

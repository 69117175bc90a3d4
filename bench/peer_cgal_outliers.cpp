#include <CGAL/compute_average_spacing.h>
#include <CGAL/property_map.h>
#include <CGAL/remove_outliers.h>

#include <utility>

#include "peer_cgal_common.h"

namespace scanclean::bench {

std::vector<std::uint8_t> cgal_remove_outliers(const Points& in, unsigned k,
                                               double threshold_percent,
                                               double threshold_distance) {
  using namespace cgal_peer;
  using Indexed = std::pair<Point, std::size_t>;
  std::vector<Indexed> pts;
  pts.reserve(in.size());
  for (std::size_t i = 0; i < in.size(); ++i)
    pts.emplace_back(Point(in[i].x(), in[i].y(), in[i].z()), i);
  auto first_removed = CGAL::remove_outliers<Concurrency>(
      pts, k,
      CGAL::parameters::point_map(CGAL::First_of_pair_property_map<Indexed>())
          .threshold_percent(threshold_percent)
          .threshold_distance(threshold_distance));
  std::vector<std::uint8_t> keep(in.size(), 1);
  for (auto it = first_removed; it != pts.end(); ++it) keep[it->second] = 0;
  return keep;
}

double cgal_average_spacing(const Points& in, unsigned k) {
  using namespace cgal_peer;
  std::vector<Point> pts = to_cgal(in);
  return CGAL::compute_average_spacing<Concurrency>(pts, k);
}

}  // namespace scanclean::bench

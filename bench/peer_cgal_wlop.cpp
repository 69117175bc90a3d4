#include <CGAL/wlop_simplify_and_regularize_point_set.h>

#include <iterator>

#include "peer_cgal_common.h"

namespace scanclean::bench {

Points cgal_wlop(const Points& in, double select_percentage, double neighbor_radius,
                 unsigned iterations) {
  using namespace cgal_peer;
  std::vector<Point> pts = to_cgal(in);
  std::vector<Point> result;
  auto np = CGAL::parameters::select_percentage(select_percentage)
                .number_of_iterations(iterations)
                .neighbor_radius(neighbor_radius > 0 ? neighbor_radius : -1.0);
  CGAL::wlop_simplify_and_regularize_point_set<Concurrency>(pts, std::back_inserter(result), np);
  Points out;
  out.reserve(result.size());
  for (const auto& p : result) out.push_back(to_eigen(p));
  return out;
}

}  // namespace scanclean::bench

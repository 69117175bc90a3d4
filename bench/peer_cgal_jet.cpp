#include <CGAL/jet_smooth_point_set.h>

#include "peer_cgal_common.h"

namespace scanclean::bench {

Points cgal_jet_smooth(const Points& in, unsigned k) {
  using namespace cgal_peer;
  std::vector<Point> pts = to_cgal(in);
  CGAL::jet_smooth_point_set<Concurrency>(pts, k);
  Points out;
  out.reserve(pts.size());
  for (const auto& p : pts) out.push_back(to_eigen(p));
  return out;
}

}  // namespace scanclean::bench

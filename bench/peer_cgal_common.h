#pragma once
// Private to the peer_cgal_*.cpp files: CGAL kernel and conversions. Never include elsewhere.

#include <CGAL/Simple_cartesian.h>
#include <CGAL/tags.h>

#include "peers.h"

namespace scanclean::bench::cgal_peer {

using Kernel = CGAL::Simple_cartesian<double>;
using Point = Kernel::Point_3;
using Vector = Kernel::Vector_3;
using Concurrency = CGAL::Parallel_if_available_tag;

inline std::vector<Point> to_cgal(const Points& in) {
  std::vector<Point> out;
  out.reserve(in.size());
  for (const auto& p : in) out.emplace_back(p.x(), p.y(), p.z());
  return out;
}

inline Eigen::Vector3d to_eigen(const Point& p) {
  return {p.x(), p.y(), p.z()};
}

}  // namespace scanclean::bench::cgal_peer

// CGAL advancing-front surface reconstruction with an edge-length limit.
#include <CGAL/Advancing_front_surface_reconstruction.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Random.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <climits>
#include <cstdint>
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

// Rotates t to start at its smallest index (orientation kept).
void rotate_to_min(std::array<int, 3>& t) {
  std::rotate(t.begin(), std::min_element(t.begin(), t.end()), t.end());
}

// CGAL lists the facets in an order that follows memory addresses, and orients each connected
// piece either way. Makes both canonical: every piece oriented so that its signed volume (about
// its first vertex) is positive, i.e. closed pieces face outwards (ties: the orientation whose
// smallest triangle is smaller), then every triangle rotated to its smallest index and sorted.
void canonical_order(const std::vector<Eigen::Vector3d>& p, std::vector<std::array<int, 3>>& tris) {
  const std::size_t nf = tris.size();
  std::vector<std::uint32_t> parent(nf);
  for (std::size_t f = 0; f < nf; ++f) parent[f] = static_cast<std::uint32_t>(f);
  auto find = [&](std::uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  std::vector<std::array<std::uint32_t, 3>> edges;  // (min, max, face)
  edges.reserve(3 * nf);
  for (std::size_t f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) {
      auto a = static_cast<std::uint32_t>(tris[f][static_cast<std::size_t>(k)]);
      auto b = static_cast<std::uint32_t>(tris[f][static_cast<std::size_t>((k + 1) % 3)]);
      edges.push_back({std::min(a, b), std::max(a, b), static_cast<std::uint32_t>(f)});
    }
  std::sort(edges.begin(), edges.end());
  for (std::size_t i = 1; i < edges.size(); ++i)
    if (edges[i][0] == edges[i - 1][0] && edges[i][1] == edges[i - 1][1]) {
      const auto a = find(edges[i][2]), b = find(edges[i - 1][2]);
      if (a != b) parent[std::max(a, b)] = std::min(a, b);
    }
  std::vector<double> volume(nf, 0.0);
  std::vector<int> origin(nf, -1);
  std::vector<std::array<int, 3>> least(nf, {INT_MAX, 0, 0}), least_flipped(nf, {INT_MAX, 0, 0});
  for (std::size_t f = 0; f < nf; ++f) {
    const auto c = find(static_cast<std::uint32_t>(f));
    auto t = tris[f];
    if (origin[c] < 0) origin[c] = std::min({t[0], t[1], t[2]});
    const Eigen::Vector3d& o = p[static_cast<std::size_t>(origin[c])];
    const Eigen::Vector3d a = p[static_cast<std::size_t>(t[0])] - o,
                          b = p[static_cast<std::size_t>(t[1])] - o,
                          d = p[static_cast<std::size_t>(t[2])] - o;
    volume[c] += a.dot(b.cross(d));
    rotate_to_min(t);
    least[c] = std::min(least[c], t);
    std::array<int, 3> r{t[0], t[2], t[1]};
    least_flipped[c] = std::min(least_flipped[c], r);
  }
  for (std::size_t f = 0; f < nf; ++f) {
    const auto c = find(static_cast<std::uint32_t>(f));
    const bool flip = volume[c] < 0 || (volume[c] == 0 && least_flipped[c] < least[c]);
    if (flip) std::swap(tris[f][1], tris[f][2]);
    rotate_to_min(tris[f]);
  }
  std::sort(tris.begin(), tris.end());
}

}  // namespace

std::vector<std::array<int, 3>> advancing_front(const std::vector<Eigen::Vector3d>& points,
                                                double max_edge, double radius_ratio_bound,
                                                double beta) {
  // The Delaunay triangulation's spatial sort shuffles with CGAL's default random generator,
  // which is seeded from the clock; on degenerate (e.g. cospherical) configurations the
  // triangulation, and so the mesh, depends on that order. Seed it: same input, same mesh.
  CGAL::get_default_random() = CGAL::Random(0);
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
  canonical_order(points, out);
  return out;
}

}  // namespace scanclean::mesh_detail

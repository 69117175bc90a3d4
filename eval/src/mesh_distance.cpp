#include "scanclean/eval/mesh_distance.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>

#include "scanclean/core/errors.h"

namespace scanclean {

Eigen::Vector3d closest_point_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                          const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  // Voronoi regions of the triangle: vertices, edges, face (barycentric tests).
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double denom = d1 - d3;
    return denom > 0 ? Eigen::Vector3d(a + (d1 / denom) * ab) : a;
  }
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double denom = d2 - d6;
    return denom > 0 ? Eigen::Vector3d(a + (d2 / denom) * ac) : a;
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double denom = (d4 - d3) + (d5 - d6);
    return denom > 0 ? Eigen::Vector3d(b + ((d4 - d3) / denom) * (c - b)) : b;
  }
  const double sum = va + vb + vc;
  if (!(sum > 0)) {
    // Degenerate (collinear) triangle that fell through: best of the three edges.
    auto seg = [&p](const Eigen::Vector3d& s, const Eigen::Vector3d& e) {
      const Eigen::Vector3d d = e - s;
      const double len2 = d.squaredNorm();
      const double t = len2 > 0 ? std::clamp((p - s).dot(d) / len2, 0.0, 1.0) : 0.0;
      return Eigen::Vector3d(s + t * d);
    };
    Eigen::Vector3d best = seg(a, b);
    for (const Eigen::Vector3d& q : {seg(b, c), seg(c, a)})
      if ((q - p).squaredNorm() < (best - p).squaredNorm()) best = q;
    return best;
  }
  const double v = vb / sum, w = vc / sum;
  return a + v * ab + w * ac;
}

MeshDistance::MeshDistance(const TriangleMesh& mesh) {
  if (mesh.triangles.empty()) throw InputError("mesh", "", "no triangles; expected at least one");
  if (mesh.triangles.size() >= std::numeric_limits<std::uint32_t>::max() / 2)
    throw InputError("mesh", "", "too many triangles");
  const std::size_t t = mesh.triangles.size();
  std::vector<Eigen::Vector3d> centroids(t);
  tri_index_.resize(t);
  for (std::size_t i = 0; i < t; ++i) {
    for (int k = 0; k < 3; ++k) {
      const int v = mesh.triangles[i][k];
      if (v < 0 || static_cast<std::size_t>(v) >= mesh.vertices.size())
        throw InputError("mesh", "triangle " + std::to_string(i),
                         "vertex index " + std::to_string(v) + " out of range (" +
                             std::to_string(mesh.vertices.size()) + " vertices)");
    }
    const auto& tr = mesh.triangles[i];
    centroids[i] = (mesh.vertices[tr[0]] + mesh.vertices[tr[1]] + mesh.vertices[tr[2]]) / 3.0;
    tri_index_[i] = i;
  }
  nodes_.reserve(2 * t / 4 + 2);
  build(0, static_cast<std::uint32_t>(t), centroids);
  tri_a_.resize(t);
  tri_b_.resize(t);
  tri_c_.resize(t);
  for (std::size_t s = 0; s < t; ++s) {
    const auto& tr = mesh.triangles[tri_index_[s]];
    tri_a_[s] = mesh.vertices[tr[0]];
    tri_b_[s] = mesh.vertices[tr[1]];
    tri_c_[s] = mesh.vertices[tr[2]];
  }
  // Leaf boxes must bound the triangles themselves, not only their centroids: refit bottom-up.
  for (std::size_t i = nodes_.size(); i-- > 0;) {
    Node& n = nodes_[i];
    if (n.count > 0) {
      n.lo = n.hi = tri_a_[n.first];
      for (std::uint32_t s = n.first; s < n.first + n.count; ++s)
        for (const Eigen::Vector3d* v : {&tri_a_[s], &tri_b_[s], &tri_c_[s]}) {
          n.lo = n.lo.cwiseMin(*v);
          n.hi = n.hi.cwiseMax(*v);
        }
    } else {
      n.lo = nodes_[n.left].lo.cwiseMin(nodes_[n.right].lo);
      n.hi = nodes_[n.left].hi.cwiseMax(nodes_[n.right].hi);
    }
  }
}

std::uint32_t MeshDistance::build(std::uint32_t begin, std::uint32_t end,
                                  std::vector<Eigen::Vector3d>& centroids) {
  const auto self = static_cast<std::uint32_t>(nodes_.size());
  nodes_.push_back(Node{});
  if (end - begin <= 4) {
    nodes_[self].first = begin;
    nodes_[self].count = end - begin;
    return self;
  }
  Eigen::Vector3d lo = centroids[tri_index_[begin]], hi = lo;
  for (std::uint32_t i = begin; i < end; ++i) {
    lo = lo.cwiseMin(centroids[tri_index_[i]]);
    hi = hi.cwiseMax(centroids[tri_index_[i]]);
  }
  int axis = 0;
  (hi - lo).maxCoeff(&axis);
  const std::uint32_t mid = begin + (end - begin) / 2;
  std::nth_element(tri_index_.begin() + begin, tri_index_.begin() + mid, tri_index_.begin() + end,
                   [&](std::size_t x, std::size_t y) {
                     return centroids[x][axis] < centroids[y][axis] ||
                            (centroids[x][axis] == centroids[y][axis] && x < y);
                   });
  const std::uint32_t l = build(begin, mid, centroids);
  const std::uint32_t r = build(mid, end, centroids);
  nodes_[self].left = l;
  nodes_[self].right = r;
  return self;
}

namespace {
double box_distance2(const Eigen::Vector3d& p, const Eigen::Vector3d& lo,
                     const Eigen::Vector3d& hi) {
  const Eigen::Vector3d d = (lo - p).cwiseMax(p - hi).cwiseMax(0.0);
  return d.squaredNorm();
}
}  // namespace

MeshDistance::Hit MeshDistance::query(const Eigen::Vector3d& p) const {
  Hit best;
  double best_d2 = std::numeric_limits<double>::infinity();
  std::uint32_t stack[128];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& n = nodes_[stack[--top]];
    if (box_distance2(p, n.lo, n.hi) >= best_d2) continue;
    if (n.count > 0) {
      for (std::uint32_t s = n.first; s < n.first + n.count; ++s) {
        const Eigen::Vector3d q = closest_point_on_triangle(p, tri_a_[s], tri_b_[s], tri_c_[s]);
        const double d2 = (q - p).squaredNorm();
        if (d2 < best_d2) {
          best_d2 = d2;
          best.point = q;
          best.triangle = tri_index_[s];
        }
      }
      continue;
    }
    const double dl = box_distance2(p, nodes_[n.left].lo, nodes_[n.left].hi);
    const double dr = box_distance2(p, nodes_[n.right].lo, nodes_[n.right].hi);
    const bool left_first = dl <= dr;
    const std::uint32_t near = left_first ? n.left : n.right, far = left_first ? n.right : n.left;
    const double dnear = left_first ? dl : dr, dfar = left_first ? dr : dl;
    if (dfar < best_d2) stack[top++] = far;
    if (dnear < best_d2) stack[top++] = near;
  }
  best.distance = std::sqrt(best_d2);
  return best;
}

}  // namespace scanclean

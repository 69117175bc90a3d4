#include "orientation.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <utility>

#include "neighbor_index.h"
#include "parallel.h"
#include "radix_sort.h"

namespace scanclean::detail {
namespace {

// A union-find whose roots are their trees' smallest nodes, and which keeps each node's parity
// against its parent (1: its normal turns relative to the parent's).
class ParityForest {
 public:
  explicit ParityForest(std::size_t n) : parent_(n), parity_(n, 0) {
    for (std::size_t i = 0; i < n; ++i) parent_[i] = static_cast<std::uint32_t>(i);
  }
  // The root of a and a's parity against it; the path is compressed on the way.
  std::pair<std::uint32_t, std::uint8_t> find(std::uint32_t a) {
    std::uint32_t root = a;
    std::uint8_t parity = 0;
    while (parent_[root] != root) {
      parity ^= parity_[root];
      root = parent_[root];
    }
    std::uint8_t left = parity;  // the parity of node a (below) against the root
    while (a != root && parent_[a] != root) {
      const std::uint32_t next = parent_[a];
      const std::uint8_t own = parity_[a];
      parent_[a] = root;
      parity_[a] = left;
      left ^= own;
      a = next;
    }
    return {root, parity};
  }
  // Joins the trees of a and b so that their parities differ by `opposite`; false if they are
  // in one tree already.
  bool join(std::uint32_t a, std::uint32_t b, bool opposite) {
    const auto [ra, pa] = find(a);
    const auto [rb, pb] = find(b);
    if (ra == rb) return false;
    const std::uint32_t lo = std::min(ra, rb), hi = std::max(ra, rb);
    parent_[hi] = lo;
    parity_[hi] = static_cast<std::uint8_t>(pa ^ pb ^ (opposite ? 1 : 0));
    return true;
  }

 private:
  std::vector<std::uint32_t> parent_;
  std::vector<std::uint8_t> parity_;
};

}  // namespace

SpanningForest orient_along_spanning_forest(std::size_t n, std::vector<OrientationEdge>& edges) {
  {
    std::vector<OrientationEdge> scratch;
    stable_radix_sort(
        edges, [](const OrientationEdge& e) { return std::uint64_t{float_order_key(e.weight)}; },
        scratch);
  }
  ParityForest uf(n);
  SpanningForest f;
  std::vector<std::uint8_t> joined(n, 0);  // per node: on at least one forest edge
  for (const OrientationEdge& e : edges)
    if (uf.join(e.a, e.b, e.opposite)) {
      f.weight += e.weight;
      joined[e.a] = joined[e.b] = 1;
    }
  f.turn.resize(n);
  f.tree.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const auto [root, parity] = uf.find(static_cast<std::uint32_t>(i));
    f.turn[i] = parity;
    f.tree[i] = root;
    f.trees += root == i && joined[i] ? 1 : 0;
  }
  return f;
}

OrientedPointNormals orient_normals(const std::vector<Eigen::Vector3f>& p, int k,
                                    const FilterOptions& o,
                                    const std::optional<Eigen::Vector3f>& viewpoint) {
  const std::size_t n = p.size();
  OrientedPointNormals out;
  out.normals.assign(n, Eigen::Vector3f::UnitZ());
  if (n < 2) return out;
  const std::size_t kk = std::min<std::size_t>(static_cast<std::size_t>(k) + 1, n);  // + itself
  const std::size_t kg = std::min<std::size_t>(kOrientationGraphNeighbours, kk - 1);
  // The grid's cell: 1.3 x a rough median distance to the kk-th point (at 1,000 points), so
  // that the 27 cells around a point nearly always hold its kk nearest (the others search
  // farther, below).
  double cell = 1.3 * rough_kth_distance(p, kk, 1000);
  if (!(cell > 0)) cell = 1e-6;
  const NeighborIndex index(p, cell);
  const float reach = index.max_adjacent_radius();
  // Everything below works on grid slots (index.order(): neighbours lie in a few runs of
  // consecutive slots), and the normals return to input order at the end.
  const std::vector<std::uint32_t>& order = index.order();
  std::vector<Eigen::Vector3f> normal(n);
  // Per slot: its PCA normal and its kg nearest others (slots).
  std::vector<std::uint32_t> near(viewpoint ? 0 : n * kg);
  parallel_each_reporting(n, o, "orientation", [&](std::size_t s) {
    const Eigen::Vector3f& q = index.slot_point(s);
    thread_local std::vector<std::pair<float, std::uint32_t>> nn;
    nn.clear();
    // Within the grid's reach, else (sparse here) within radii growing by half.
    for (float r = reach; nn.size() < kk; r *= 1.5f) {
      nn.clear();
      index.for_each_slot_within(q, r, [&](std::uint32_t j, float d2) { nn.emplace_back(d2, j); });
    }
    // The kk nearest (by distance, then slot: unique), the first kg + 1 of them in order.
    const auto mid = nn.begin() + static_cast<std::ptrdiff_t>(kk);
    if (nn.size() > kk) std::nth_element(nn.begin(), mid - 1, nn.end());
    std::partial_sort(nn.begin(), nn.begin() + static_cast<std::ptrdiff_t>(std::min(kk, kg + 1)),
                      mid);
    // One pass of float sums of the offsets from q (within a few neighbour distances: float
    // keeps them to about 1e-7 of that), the covariance formed in double.
    float sx = 0, sy = 0, sz = 0, sxx = 0, syy = 0, szz = 0, sxy = 0, sxz = 0, syz = 0;
    for (std::size_t t = 0; t < kk; ++t) {
      const Eigen::Vector3f d = index.slot_point(nn[t].second) - q;
      sx += d.x();
      sy += d.y();
      sz += d.z();
      sxx += d.x() * d.x();
      syy += d.y() * d.y();
      szz += d.z() * d.z();
      sxy += d.x() * d.y();
      sxz += d.x() * d.z();
      syz += d.y() * d.z();
    }
    const double inv = 1.0 / static_cast<double>(kk);
    const Eigen::Vector3d mean(sx * inv, sy * inv, sz * inv);
    Eigen::Matrix3d cov;
    cov << sxx * inv, sxy * inv, sxz * inv, sxy * inv, syy * inv, syz * inv, sxz * inv, syz * inv,
        szz * inv;
    cov -= mean * mean.transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
    es.computeDirect(cov);
    normal[s] = es.eigenvectors().col(0).cast<float>().normalized();
    if (viewpoint) {  // turned to face the scanner; no graph
      if (normal[s].dot(*viewpoint - q) < 0) normal[s] = -normal[s];
      return;
    }
    // The graph's neighbours: the nearest others (the point itself comes first, at distance 0,
    // unless a duplicate of it sits in an earlier slot).
    std::size_t t = 0;
    for (std::size_t u = 0; u <= kg && u < kk && t < kg; ++u)
      if (nn[u].second != s) near[s * kg + t++] = nn[u].second;
    for (; t < kg; ++t) near[s * kg + t] = static_cast<std::uint32_t>(s);  // none: a self loop
  });
  if (viewpoint) {
    parallel_each(n, [&](std::size_t s) { out.normals[order[s]] = normal[s]; });
    return out;
  }
  // The graph's edges, each pair once (a pair whose two points list each other is taken from
  // the smaller one's list), in slot order: counted, then filled.
  auto listed = [&](std::uint32_t a, std::uint32_t b) {  // b among a's neighbours
    const std::uint32_t* l = &near[static_cast<std::size_t>(a) * kg];
    return std::find(l, l + kg, b) != l + kg;
  };
  auto kept = [&](std::size_t s, std::uint32_t j) { return j > s || (j < s && !listed(j, s)); };
  std::vector<std::size_t> first(n + 1, 0);
  parallel_each(n, [&](std::size_t s) {
    std::size_t c = 0;
    for (std::size_t t = 0; t < kg; ++t) c += kept(s, near[s * kg + t]) ? 1 : 0;
    first[s + 1] = c;
  });
  for (std::size_t s = 0; s < n; ++s) first[s + 1] += first[s];
  std::vector<OrientationEdge> edges(first[n]);
  parallel_each(n, [&](std::size_t s) {
    std::size_t k = first[s];
    for (std::size_t t = 0; t < kg; ++t) {
      const std::uint32_t j = near[s * kg + t];
      if (!kept(s, j)) continue;
      const float dot = normal[s].dot(normal[j]);
      OrientationEdge& e = edges[k++];
      e.weight = 1.0f - std::min(1.0f, std::abs(dot));
      e.a = static_cast<std::uint32_t>(std::min<std::size_t>(s, j));
      e.b = static_cast<std::uint32_t>(std::max<std::size_t>(s, j));
      e.opposite = dot < 0;
    }
  });
  std::vector<std::uint32_t>().swap(near);
  const SpanningForest f = orient_along_spanning_forest(n, edges);
  std::vector<OrientationEdge>().swap(edges);
  // Each tree's highest point (largest z, then smallest slot) gets a normal pointing up.
  std::vector<std::uint32_t> top(n, static_cast<std::uint32_t>(n));
  for (std::size_t s = 0; s < n; ++s) {
    std::uint32_t& t = top[f.tree[s]];
    if (t == n || index.slot_point(s).z() > index.slot_point(t).z())
      t = static_cast<std::uint32_t>(s);
  }
  parallel_each(n, [&](std::size_t s) {
    const std::uint32_t t = top[f.tree[s]];
    const float top_z = f.turn[t] ? -normal[t].z() : normal[t].z();
    out.normals[order[s]] =
        (f.turn[s] != 0) != (top_z < 0) ? Eigen::Vector3f(-normal[s]) : normal[s];
  });
  out.trees = f.trees;
  return out;
}

}  // namespace scanclean::detail

#include "scale_selection.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>

#include "neighbor_index.h"
#include "parallel.h"
#include "point_moments.h"

namespace scanclean::detail {

namespace {

constexpr std::size_t kMaxRadii = 16;

// Moments of the neighbours in one shell, relative to the query point.
using Moments = PointMoments;

// The ICI rule over the balls made of shell[0..K): the index of the largest radius whose
// interval meets every smaller one's (-1: none; the smallest ball too sparse), and the index of
// the first ball that broke the intervals (K: none did; a ball too sparse ends the ladder
// without breaking it).
struct Ladder {
  int chosen = -1;
  std::size_t broke = 0;
};
Ladder run_ladder(const Moments* shell, std::size_t K, const ScaleSelectionOptions& o) {
  Ladder out;
  out.broke = K;
  Moments ball;
  double lo = -HUGE_VAL, hi = HUGE_VAL;
  Eigen::Vector3d n_prev = Eigen::Vector3d::Zero();
  for (std::size_t k = 0; k < K; ++k) {
    ball += shell[k];
    if (ball.n < o.k_min) break;
    const Eigen::Vector3d c = ball.mean();
    const Eigen::Matrix3d cov = ball.second() - c * c.transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
    es.computeDirect(cov);
    Eigen::Vector3d nk = es.eigenvectors().col(0);
    if (nk.dot(n_prev) < 0) nk = -nk;  // the same side as the smaller ball's normal
    n_prev = nk;
    const double z = -nk.dot(c);  // the point's signed distance to the plane
    const double var = o.sigma > 0 ? o.sigma * o.sigma : std::max(es.eigenvalues()[0], 0.0);
    const double se = std::sqrt(var / ball.n);
    lo = std::max(lo, z - o.gamma * se);
    hi = std::min(hi, z + o.gamma * se);
    if (lo > hi) {
      out.broke = k;
      break;
    }
    out.chosen = static_cast<int>(k);
  }
  return out;
}

// One neighbour of the crease test: its offset from the query point and its shell.
struct ShellPoint {
  Eigen::Vector3d q;
  std::size_t shell;
};

// The crease test (ScaleSelectionOptions::crease) on the ball of index `ball` (its radius
// `radius`) of a point whose neighbours are `around`: where that ball holds a crease the
// kernels would split, the index the ladder chooses on the point's side of it; else -1.
int own_face_ladder(const std::vector<ShellPoint>& around, std::size_t ball, double radius,
                    std::size_t K, const ScaleSelectionOptions& o) {
  // The ball's neighbours with their chi weights at its radius, as a kernel of that size
  // would weigh them.
  thread_local std::vector<FitSample> samples, untrimmed;
  samples.clear();
  const double inv_r2 = 1.0 / (radius * radius);
  for (const ShellPoint& a : around) {
    if (a.shell > ball) continue;
    const double u = 1.0 - a.q.squaredNorm() * inv_r2;
    if (!(u > 0)) continue;
    const double u2 = u * u;
    samples.push_back({a.q.x(), a.q.y(), a.q.z(), u2 * u2});
  }
  untrimmed = samples;
  KernelFit fit;
  if (!fit_samples(samples, Eigen::Vector3d::Zero(), radius, o.crease.k_min, o.crease.eigen_floor,
                   fit))
    return -1;
  CreaseSide side;
  if (!split_crease(untrimmed, Eigen::Vector3d::Zero(), o.crease, fit, &side)) return -1;
  std::array<Moments, kMaxRadii> shell;
  for (const ShellPoint& a : around)
    if (side.holds(a.q)) shell[a.shell].add(a.q.x(), a.q.y(), a.q.z());
  return run_ladder(shell.data(), K, o).chosen;
}

}  // namespace

std::vector<double> select_scale(const std::vector<Eigen::Vector3d>& p, const NeighborIndex& index,
                                 const std::vector<std::size_t>& queries,
                                 const ScaleSelectionOptions& o, std::size_t* creases) {
  const std::size_t K = std::min(o.radii.size(), kMaxRadii);
  std::vector<double> out(queries.size(), K ? o.radii.front() : 0.0);
  if (creases) *creases = 0;
  if (K == 0) return out;
  std::array<double, kMaxRadii> r2{};
  for (std::size_t k = 0; k < K; ++k) r2[k] = o.radii[k] * o.radii[k];
  const float rmax = static_cast<float>(o.radii[K - 1] * 1.0001);
  const bool crease_test = o.crease.creases();
  std::vector<std::uint8_t> raised(crease_test ? queries.size() : 0, 0);
  // The positions in the index's slot order: the neighbours of a query sit in a few runs of
  // consecutive slots (read in input order, they were scattered over the whole cloud, and the
  // loop waited on the memory). The same neighbours, in the same order.
  const std::vector<Eigen::Vector3d> ps = permuted(p, index.order());
  // The radius index chosen for query qi; `around` receives its neighbours for the crease test.
  auto choose = [&](std::size_t qi, std::vector<ShellPoint>& around) {
    const std::size_t i = queries[qi];
    const Eigen::Vector3d& x = p[i];
    // Shell k holds the neighbours with r_{k-1} < |q| <= r_k; the balls are their sums.
    std::array<Moments, kMaxRadii> shell;
    around.clear();
    const std::uint32_t own = index.slot_of(static_cast<std::uint32_t>(i));
    index.for_each_slot_within(x.cast<float>(), rmax, [&](std::uint32_t j, float) {
      if (j == own) return;
      const Eigen::Vector3d q = ps[j] - x;
      const double d2 = q.squaredNorm();
      std::size_t k = 0;  // the first radius at or beyond |q|
      for (std::size_t r = 0; r < K; ++r) k += d2 > r2[r] ? 1 : 0;
      if (k < K) {
        shell[k].add(q.x(), q.y(), q.z());
        if (crease_test) around.push_back({q, k});
      }
    });
    const Ladder l = run_ladder(shell.data(), K, o);
    if (crease_test && l.broke < K) {
      int face = -1;
      for (std::size_t b = l.broke; b < K && face < 0; ++b)
        face = own_face_ladder(around, b, o.radii[b], K, o);
      if (face == static_cast<int>(K) - 1 && face > l.chosen) {
        raised[qi] = 1;
        return face;
      }
    }
    return l.chosen;
  };
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, queries.size(), 64),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      thread_local std::vector<ShellPoint> around;
                      for (std::size_t qi = range.begin(); qi < range.end(); ++qi)
                        if (const int k = choose(qi, around); k >= 0)
                          out[qi] = o.radii[static_cast<std::size_t>(k)];
                    });
  if (creases)
    for (const std::uint8_t r : raised) *creases += r;
  return out;
}

std::vector<float> region_scales(const NeighborIndex& cells, std::vector<Eigen::Vector3f> samples,
                                 const std::vector<double>& radii, std::size_t k) {
  const std::size_t n = cells.size();
  std::vector<float> out(n, 0.0f);
  if (samples.empty() || k == 0) return out;
  const NeighborIndex tree(std::move(samples), 0.0);  // k-d tree only
  const std::vector<std::uint32_t>& id = cells.order();
  // Groups of slots [b, e) sharing one scale: the grid's cells, or single points.
  const bool by_cell = cells.cell_count() > 0;
  const std::size_t groups = by_cell ? cells.cell_count() : n;
  auto begin = [&](std::size_t g) { return by_cell ? cells.cell_begin(g) : g; };
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, groups, 256),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      std::vector<std::pair<float, std::uint32_t>> nn;
                      std::vector<double> near;
                      for (std::size_t g = r.begin(); g != r.end(); ++g) {
                        const std::size_t b = begin(g), e = begin(g + 1);
                        Eigen::Vector3f c = Eigen::Vector3f::Zero();
                        for (std::size_t s = b; s < e; ++s) c += cells.slot_point(s);
                        c /= static_cast<float>(e - b);
                        tree.knn(c, k, nn);
                        near.clear();
                        for (const auto& [d2, j] : nn) near.push_back(radii[j]);
                        std::sort(near.begin(), near.end());
                        const std::size_t m = near.size();
                        const float v = static_cast<float>(
                            m % 2 == 1 ? near[m / 2] : 0.5 * (near[m / 2 - 1] + near[m / 2]));
                        for (std::size_t s = b; s < e; ++s) out[id[s]] = v;
                      }
                    });
  return out;
}

}  // namespace scanclean::detail

#include "outlier_tests.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <numeric>

#include "cell_select.h"
#include "neighbor_index.h"
#include "parallel.h"
#include "select.h"

namespace scanclean::detail {
namespace {

// The displacement test computes the median and MAD of the moves around every
// kDisplacementAnchor-th representative (in grid order) and screens the points near it with them.
constexpr std::size_t kDisplacementAnchor = 8;

std::uint32_t find_root(std::vector<std::uint32_t>& parent, std::uint32_t a) {
  while (parent[a] != a) {
    parent[a] = parent[parent[a]];
    a = parent[a];
  }
  return a;
}

}  // namespace

std::vector<std::uint8_t> sparse_support(const std::vector<float>& support, double tau,
                                         const std::vector<std::uint8_t>* strides) {
  std::vector<std::uint8_t> sparse(support.size(), 0);
  if (support.empty() || !(tau > 0)) return sparse;
  std::vector<float> v;
  for (std::size_t i = 0; i < support.size(); ++i)
    if (support[i] >= 0) v.insert(v.end(), strides ? (*strides)[i] : 1, support[i]);
  const double limit = tau * static_cast<double>(median_of(std::move(v)));
  parallel_each(support.size(), [&](std::size_t i) {
    if (support[i] >= 0 && support[i] < limit) sparse[i] = 1;
  });
  return sparse;
}

std::vector<Removal> test_representatives(const RepresentativeTestInput& in,
                                          const FilterOptions& o) {
  // Index spaces: points (the filter's grid order: x, pr, d, src), representatives r (cl) and
  // representative slots s (the order of ridx, spatially coherent), in which the tests work.
  const Clusters& cl = *in.clusters;
  const std::vector<Eigen::Vector3d>& x = *in.x;
  const Projected& pr = *in.projected;
  const PointSet& d = *in.points;
  const std::vector<std::uint32_t>& src = *in.input_index;
  const std::size_t R = cl.seed.size();
  std::vector<Removal> rep_drop(R, Removal::kKept);
  if (R > 0 && (o.tau > 0 || o.likelihood_ratio > 0 || o.displacement_sigma > 0 ||
                o.remove_small_components)) {
    std::vector<Eigen::Vector3f> rf(R);
    parallel_each(R, [&](std::size_t r) { rf[r] = cl.position[r].cast<float>(); });
    NeighborIndex ridx(std::move(rf), in.cell * 1.001);
    // Work in the index's slot order (spatially coherent).
    const std::vector<std::uint32_t>& rord = ridx.order();
    std::vector<std::uint32_t> cnt(R);
    std::vector<float> hs(R);
    parallel_each(R, [&](std::size_t s) {
      cnt[s] = cl.count[rord[s]];
      hs[s] = static_cast<float>(d.hi_at(cl.seed[rord[s]]));
    });
    std::vector<Removal> drop(R, Removal::kKept);
    if (o.tau > 0 || o.likelihood_ratio > 0 || o.displacement_sigma > 0) {
      // One pass over the output points within h of each: the density rho (input points they
      // stand for), for the likelihood-ratio test the lower quartile of their likelihoods, and
      // at the anchors the displacement test's statistics (a second pass finishes that test).
      // A point that stopped off the surface (a near outlier supported by the surface kernels,
      // or by its own kernel, which its own weight stretches towards it) has a likelihood far
      // below that of the surface points around it; a point of a sparse region or at a rim
      // does not, as its neighbours are as sparse. The lower quartile, not the median: a point
      // on a rim or in a corner has neighbours with up to 4x its L (measured: the median
      // dropped 0.5 % of a clean square's points, all within h of its border; the lower
      // quartile 0.16 %, with the same outliers found).
      const bool by_l = o.likelihood_ratio > 0;
      std::vector<float> lik(by_l ? R : 0);
      if (by_l) parallel_each(R, [&](std::size_t s) { lik[s] = pr.L[cl.seed[rord[s]]]; });
      // Displacement test: how far each output point's seed moved along its normal.
      const bool by_d = o.displacement_sigma > 0;
      std::vector<float> moved(by_d ? R : 0);
      if (by_d)
        parallel_each(R, [&](std::size_t s) {
          const std::uint32_t i = cl.seed[rord[s]];
          const Eigen::Vector3d step = x[i] - ((*in.input_positions)[src[i]] - in.origin);
          moved[s] = static_cast<float>(step.dot(pr.normal[i].cast<double>()));
        });
      // When the kernels are thinned (h raised for the noise), so is this pass: both sums run
      // over every stride-th output point (slots are in grid order: an even subsample, about
      // K_h of them within h instead of K_h stride), and rho is scaled back by the stride. With
      // a stride of 1 both are exact.
      const std::size_t stride = in.stride;
      std::unique_ptr<NeighborIndex> thinned;
      if (stride > 1) {
        std::vector<Eigen::Vector3f> sub((R + stride - 1) / stride);
        parallel_each(sub.size(), [&](std::size_t k) { sub[k] = ridx.slot_point(k * stride); });
        thinned = std::make_unique<NeighborIndex>(std::move(sub), in.cell * 1.001);
      }
      // The values the passes read of the points around: with a thinned index, copied into its
      // slot order, so that the points of a query's cells are read from consecutive entries.
      const std::size_t T = thinned ? thinned->size() : 0;
      std::vector<std::uint32_t> cnt_t(T);
      std::vector<float> lik_t(by_l ? T : 0), moved_t(by_d ? T : 0);
      if (thinned) {
        const std::vector<std::uint32_t>& id = thinned->order();
        parallel_each(T, [&](std::size_t t) {
          const std::size_t q = id[t] * stride;
          cnt_t[t] = cnt[q];
          if (by_l) lik_t[t] = lik[q];
          if (by_d) moved_t[t] = moved[q];
        });
      }
      const std::uint32_t* around_cnt = thinned ? cnt_t.data() : cnt.data();
      const float* around_lik = thinned ? lik_t.data() : lik.data();
      const float* around_moved = thinned ? moved_t.data() : moved.data();
      // Through the per-thread cell cache (cell_select.h): the same points as the index's own
      // radius query, in its order; each indexes around_cnt, around_lik and around_moved.
      // Without the cache's parts: on the 2.1M-point sphere at k = 250 a part served three
      // queries and cost more to make than it saved.
      const std::uint64_t cell_key = new_cell_cache_key();
      // The points around s: a pointer to them (valid until the next call) and their count.
      auto around = [&](std::size_t s) {
        return thread_cell_select().slots_within(thinned ? *thinned : ridx, cell_key,
                                                 ridx.slot_point(s), hs[s], false);
      };
      // Displacement test: the median of the moves around s and 1.4826 x their median absolute
      // deviation (the robust standard deviation), floored at 0.02 h; none (scale 0) when fewer
      // than 8 points are around. `around` is overwritten.
      struct MoveStats {
        float median = 0, scale = 0;
      };
      auto move_stats = [&](std::vector<float>& around, std::size_t s) {
        MoveStats m;
        const std::size_t n = around.size();
        if (n < 8) return m;
        // Both selections by bins over the values' range (select.h), exact.
        float lo = around[0], hi = around[0];
        for (float v : around) {
          lo = std::min(lo, v);
          hi = std::max(hi, v);
        }
        thread_local std::vector<float> scratch;  // the selection overwrites its input
        scratch.assign(around.begin(), around.end());
        m.median = kth_smallest_between(scratch.data(), n, n / 2, lo, hi);
        for (float& v : around) v = std::abs(v - m.median);
        const float mad =
            kth_smallest_below(around.data(), n, n / 2, std::max(hi - m.median, m.median - lo));
        m.scale = std::max(1.4826f * mad, 0.02f * hs[s]);
        return m;
      };
      auto is_displaced = [&](std::size_t s, const MoveStats& m) {
        return m.scale > 0 && static_cast<double>(std::abs(moved[s] - m.median)) >
                                  o.displacement_sigma * static_cast<double>(m.scale);
      };
      // The points around in a struct of arrays (the around index's slot order), for the
      // one-pass counts of points that are not anchors (select.h count_within).
      const NeighborIndex& aidx = thinned ? *thinned : ridx;
      std::vector<float> ax(aidx.size()), ay(aidx.size()), az(aidx.size());
      parallel_each(aidx.size(), [&](std::size_t t) {
        const Eigen::Vector3f& p = aidx.slot_point(t);
        ax[t] = p.x();
        ay[t] = p.y();
        az[t] = p.z();
      });
      std::vector<double> rho(R, 0.0);
      std::vector<std::uint8_t> low_l(by_l ? R : 0, 0);
      const std::size_t anchors = by_d ? (R + kDisplacementAnchor - 1) / kDisplacementAnchor : 0;
      std::vector<MoveStats> anchor_stats(anchors);
      const SelectLoops loops = select_loops();  // dispatched once, called per run
      parallel_each(R, [&](std::size_t s) {
        thread_local std::vector<float> around_d;
        const bool anchor = by_d && s % kDisplacementAnchor == 0;
        // Likelihood ratio: L_s < ratio x Q1, Q1 the element at rank floor(n / 4) of the n
        // likelihoods around, holds exactly when at most floor(n / 4) of them have ratio x L_q
        // <= L_s (ratio x L is monotone in L), so a count replaces the selection. No points
        // around (s is off the thinned subsample, and alone): Q1 would be L_s itself, kept.
        const double l_s = by_l ? static_cast<double>(lik[s]) : 0.0;
        // Not an anchor, on the grid's fast path: the same points, counted in one pass.
        const float r = hs[s];
        const std::int64_t c = !anchor && r > 0 ? aidx.adjacent_cell(ridx.slot_point(s), r) : -1;
        float bound = 0;
        if (c >= 0 && (!by_l || largest_float_scaled_at_or_below(o.likelihood_ratio, l_s, bound))) {
          const Eigen::Vector3f& q = ridx.slot_point(s);
          const float qa[3] = {q.x(), q.y(), q.z()};
          WithinCounts w;
          aidx.for_each_adjacent_run(
              static_cast<std::size_t>(c), [&](std::uint32_t b, std::uint32_t e) {
                loops.count_within(ax.data() + b, ay.data() + b, az.data() + b, around_cnt + b,
                                   by_l ? around_lik + b : nullptr, e - b, qa, r * r, bound, w);
              });
          rho[s] = static_cast<double>(w.sum) * static_cast<double>(stride);
          if (by_l) low_l[s] = w.n > 0 && w.at_or_below <= w.n / 4 ? 1 : 0;
          return;
        }
        std::uint64_t sum = 0;
        std::size_t n_l = 0, at_or_below = 0;
        const auto [hits, na] = around(s);
        if (anchor) around_d.resize(na);
        for (std::size_t k = 0; k < na; ++k) {
          const std::uint32_t a = hits[k];
          sum += around_cnt[a];
          if (by_l) {
            ++n_l;
            at_or_below += o.likelihood_ratio * static_cast<double>(around_lik[a]) <= l_s ? 1 : 0;
          }
          if (anchor) around_d[k] = around_moved[a];
        }
        rho[s] = static_cast<double>(sum) * static_cast<double>(stride);
        if (by_l) low_l[s] = n_l > 0 && at_or_below <= n_l / 4 ? 1 : 0;
        if (anchor) anchor_stats[s / kDisplacementAnchor] = move_stats(around_d, s);
      });
      // Screen: a point whose move lies within half the threshold of the median of an anchor
      // around it within h (2 robust deviations at the default 4; the four anchors nearest in
      // grid order) is kept; every other point gets the test with its own statistics. The
      // screen saves time (the statistics change slowly over h): at 1M points 5 % of them were
      // left to requery with the two nearest anchors, and against the test at every point it
      // kept 1 of the 4,792 points the latter dropped on the real bunny scans (6 with four).
      std::vector<std::uint8_t> displaced(by_d ? R : 0, 0);
      if (by_d)
        parallel_each(R, [&](std::size_t s) {
          if (s % kDisplacementAnchor == 0) {
            displaced[s] = is_displaced(s, anchor_stats[s / kDisplacementAnchor]) ? 1 : 0;
            return;
          }
          // The anchors just before and after s in grid order, and the next ones on either side:
          // s passes the screen with any of them within h of it. (With the two nearest alone,
          // 110,000 of the 1.9M points of the 2.1M-point sphere at k = 250 had neither within h,
          // at cell boundaries of the grid order, and were tested with statistics of their own.)
          const std::size_t a0 = s / kDisplacementAnchor;
          for (std::size_t a = a0 > 0 ? a0 - 1 : 0; a <= a0 + 2 && a < anchors; ++a) {
            const float d2 =
                (ridx.slot_point(s) - ridx.slot_point(a * kDisplacementAnchor)).squaredNorm();
            const MoveStats& m = anchor_stats[a];
            if (m.scale > 0 && d2 <= hs[s] * hs[s] &&
                static_cast<double>(std::abs(moved[s] - m.median)) <=
                    0.5 * o.displacement_sigma * static_cast<double>(m.scale))
              return;
          }
          thread_local std::vector<float> around_d;
          const auto [hits, na] = around(s);
          around_d.resize(na);
          for (std::size_t k = 0; k < na; ++k) around_d[k] = around_moved[hits[k]];
          displaced[s] = is_displaced(s, move_stats(around_d, s)) ? 1 : 0;
        });
      const double threshold = o.tau > 0 ? o.tau * median_of(rho) : 0.0;
      for (std::size_t s = 0; s < R; ++s) {
        if (rho[s] < threshold)
          drop[s] = Removal::kLowDensity;
        else if (by_l && low_l[s])
          drop[s] = Removal::kLowLikelihood;
        else if (by_d && displaced[s])
          drop[s] = Removal::kDisplaced;
      }
    }
    if (o.remove_small_components) {
      std::vector<std::uint32_t> parent(R);
      std::iota(parent.begin(), parent.end(), 0u);
      for (std::size_t s = 0; s < R; ++s) {
        if (drop[s] != Removal::kKept) continue;
        ridx.for_each_slot_within(ridx.slot_point(s), hs[s], [&](std::uint32_t q, float) {
          if (q <= s || drop[q] != Removal::kKept) return;
          const std::uint32_t a = find_root(parent, static_cast<std::uint32_t>(s));
          const std::uint32_t b = find_root(parent, q);
          if (a != b) parent[std::max(a, b)] = std::min(a, b);
        });
      }
      std::vector<std::uint64_t> size(R, 0);
      for (std::size_t s = 0; s < R; ++s)
        if (drop[s] == Removal::kKept)
          size[find_root(parent, static_cast<std::uint32_t>(s))] += cnt[s];
      const std::uint64_t min_size =
          o.min_component_size > 0
              ? o.min_component_size
              : std::max<std::uint64_t>(static_cast<std::uint64_t>(o.k_min),
                                        static_cast<std::uint64_t>(
                                            std::ceil(1e-3 * static_cast<double>(in.points_in))));
      for (std::size_t s = 0; s < R; ++s)
        if (drop[s] == Removal::kKept &&
            size[find_root(parent, static_cast<std::uint32_t>(s))] < min_size)
          drop[s] = Removal::kSmallComponent;
    }
    for (std::size_t s = 0; s < R; ++s) rep_drop[rord[s]] = drop[s];
  }

  return rep_drop;
}

}  // namespace scanclean::detail

#include "outlier_tests.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include "cell_groups.h"
#include "neighbor_index.h"
#include "parallel.h"
#include "select.h"

namespace scanclean::detail {
namespace {

// The displacement test computes the median and MAD of the moves around every
// kDisplacementAnchor-th representative (in grid order) and screens the points near it with them.
constexpr std::size_t kDisplacementAnchor = 8;

// The around points near a group of queries, copied compactly (select_near_box) with their
// around index, count and likelihood; padded with +inf to a multiple of 8 for select_within.
struct NearPoints {
  std::vector<float> x, y, z, lik;
  std::vector<std::uint32_t> at, cnt;
  std::size_t n = 0;
  // Room for m points and the padding or a whole vector past them.
  void reserve(std::size_t m) {
    if (x.size() >= m + kStoreSlack) return;
    for (auto* v : {&x, &y, &z, &lik}) v->resize(2 * m + kStoreSlack);
    for (auto* v : {&at, &cnt}) v->resize(2 * m + kStoreSlack);
  }
  void clear() { n = 0; }
  void push(float px, float py, float pz, std::uint32_t t, std::uint32_t c, float l) {
    reserve(n + 1);
    x[n] = px;
    y[n] = py;
    z[n] = pz;
    at[n] = t;
    cnt[n] = c;
    lik[n] = l;
    ++n;
  }
  std::size_t padded() const { return (n + 7) / 8 * 8; }
  void pad() {
    constexpr float kInf = std::numeric_limits<float>::infinity();
    for (std::size_t k = n; k < padded(); ++k) {
      x[k] = y[k] = z[k] = kInf;
      at[k] = cnt[k] = 0;
      lik[k] = 0;
    }
  }
};

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
    NeighborIndex ridx(std::move(rf), grid_cell_for(in.cell));
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
      // over the around points, every stride-th output point (slots are in grid order: an even
      // subsample, about K_h of them within h instead of K_h stride), and rho is scaled back by
      // the stride. With a stride of 1 both are exact. Around point t is slot t * stride; the
      // values the passes read of it are copied in that order, so that the around points of a
      // cell's neighbourhood are consecutive.
      const std::size_t stride = in.stride;
      const std::size_t T = (R + stride - 1) / stride;
      std::vector<float> ax(T), ay(T), az(T);
      std::vector<std::uint32_t> at(T);  // t itself, which the compact copies carry along
      std::vector<std::uint32_t> cnt_t(stride > 1 ? T : 0);
      std::vector<float> lik_t(by_l && stride > 1 ? T : 0), moved_t(by_d && stride > 1 ? T : 0);
      parallel_each(T, [&](std::size_t t) {
        const std::size_t q = t * stride;
        const Eigen::Vector3f& p = ridx.slot_point(q);
        ax[t] = p.x();
        ay[t] = p.y();
        az[t] = p.z();
        at[t] = static_cast<std::uint32_t>(t);
        if (stride > 1) {
          cnt_t[t] = cnt[q];
          if (by_l) lik_t[t] = lik[q];
          if (by_d) moved_t[t] = moved[q];
        }
      });
      const std::uint32_t* around_cnt = stride > 1 ? cnt_t.data() : cnt.data();
      const float* around_lik = stride > 1 ? lik_t.data() : lik.data();
      const float* around_moved = stride > 1 ? moved_t.data() : moved.data();
      const SelectLoops loops = select_loops();  // dispatched once, called per run
      // Calls f(s, near) for each slot s of cell c of ridx with want(s); near holds every around
      // point within hs[s] of s, among others. Slots whose h lies within the grid's reach go in
      // octant groups (cell_groups.h), each with the around points within its largest h of its
      // box, copied from the 27 cells' runs (on the 2.1M-point sphere at k = 250, 370 points
      // per query instead of the 905 of the 27 cells); the others take the index's own query.
      auto for_cell = [&](std::size_t c, auto&& want, auto&& f) {
        struct Run {
          std::size_t b, e;        // around points [b, e)
          Eigen::Vector3f lo, hi;  // their bounding box
        };
        thread_local std::vector<Run> runs;
        thread_local std::vector<std::uint32_t> queries;
        thread_local OctantGroups groups;
        thread_local NearPoints near;
        queries.clear();
        const float reach = ridx.max_adjacent_radius();
        const std::uint32_t cb = ridx.cell_begin(c), ce = ridx.cell_begin(c + 1);
        for (std::uint32_t s = cb; s < ce; ++s) {
          if (!want(s)) continue;
          const Eigen::Vector3f& q = ridx.slot_point(s);
          // The 27 cells around c hold every point within the grid's reach of a point of c.
          if (hs[s] > 0 && hs[s] <= reach) {
            queries.push_back(s);
            continue;
          }
          // Every around point of the cells the query's ball touches (f tests the distances),
          // else (a ball too large for the grid) those the index finds within h.
          near.clear();
          auto add = [&](std::size_t t) {
            near.push(ax[t], ay[t], az[t], static_cast<std::uint32_t>(t), around_cnt[t],
                      by_l ? around_lik[t] : 0.0f);
          };
          if (!ridx.for_each_cell_run(q, hs[s], [&](std::uint32_t b, std::uint32_t e) {
                for (std::size_t t = (b + stride - 1) / stride; t < (e + stride - 1) / stride; ++t)
                  add(t);
              }))
            ridx.for_each_slot_within(q, hs[s], [&](std::uint32_t p, float) {
              if (p % stride == 0) add(p / stride);
            });
          near.pad();
          f(s, near);
        }
        if (queries.empty()) return;
        runs.clear();
        std::size_t total = 0;
        ridx.for_each_adjacent_run(c, [&](std::uint32_t b, std::uint32_t e) {
          const std::size_t tb = (b + stride - 1) / stride, te = (e + stride - 1) / stride;
          if (tb >= te) return;
          Run run{tb, te, {ax[tb], ay[tb], az[tb]}, {ax[tb], ay[tb], az[tb]}};
          for (std::size_t t = tb + 1; t < te; ++t) {
            const Eigen::Vector3f p(ax[t], ay[t], az[t]);
            run.lo = run.lo.cwiseMin(p);
            run.hi = run.hi.cwiseMax(p);
          }
          runs.push_back(run);
          total += te - tb;
        });
        near.reserve(total);
        group_by_octant(
            queries.size(),
            [&](std::size_t k) -> const Eigen::Vector3f& { return ridx.slot_point(queries[k]); },
            groups);
        for (std::uint8_t g = 0; g < 8; ++g) {
          if (groups.members[g] == 0) continue;
          float reach = 0;
          for (std::size_t k = 0; k < queries.size(); ++k)
            if (groups.octant[k] == g) reach = std::max(reach, hs[queries[k]]);
          // As in scale.cpp: the rounded squared distance to the box is at most that to any
          // query in it, so the points within a member's h are all kept; 0.1 % more to spare.
          const float w2 = reach * reach * 1.001f;
          const Eigen::Vector3f &glo = groups.lo[g], &ghi = groups.hi[g];
          const float glo3[3] = {glo.x(), glo.y(), glo.z()}, ghi3[3] = {ghi.x(), ghi.y(), ghi.z()};
          near.clear();
          for (const Run& run : runs) {
            const float g2 = (run.lo - ghi).cwiseMax(glo - run.hi).cwiseMax(0.0f).squaredNorm();
            if (g2 < w2)
              loops.select_near_box(
                  ax.data() + run.b, ay.data() + run.b, az.data() + run.b, at.data() + run.b,
                  by_l ? around_lik + run.b : nullptr, run.e - run.b, glo3, ghi3, w2,
                  {near.x.data(), near.y.data(), near.z.data(), near.at.data(), near.lik.data()},
                  near.n);
          }
          for (std::size_t k = 0; k < near.n; ++k) near.cnt[k] = around_cnt[near.at[k]];
          near.pad();
          for (std::size_t k = 0; k < queries.size(); ++k)
            if (groups.octant[k] == g) f(queries[k], near);
        }
      };
      // The around points within h of s, as around indices t, into hits; returns their count.
      auto around = [&](std::size_t s, const NearPoints& near, std::vector<std::uint32_t>& hits) {
        const Eigen::Vector3f& q = ridx.slot_point(s);
        const float qa[3] = {q.x(), q.y(), q.z()};
        hits.resize(near.padded());
        return select_within(near.x.data(), near.y.data(), near.z.data(), near.at.data(),
                             near.padded(), qa, hs[s] * hs[s], hits.data());
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
      // The moves of the around points within h of s, their statistics.
      // The statistics of the moves of the around points hits[0, na) (those within h of s).
      auto move_stats_of = [&](std::size_t s, const std::uint32_t* hits, std::size_t na) {
        thread_local std::vector<float> around_d;
        around_d.resize(na);
        for (std::size_t k = 0; k < na; ++k) around_d[k] = around_moved[hits[k]];
        return move_stats(around_d, s);
      };
      auto move_stats_at = [&](std::size_t s, const NearPoints& near) {
        thread_local std::vector<std::uint32_t> hits;
        const std::size_t na = around(s, near, hits);
        return move_stats_of(s, hits.data(), na);
      };
      auto is_displaced = [&](std::size_t s, const MoveStats& m) {
        return m.scale > 0 && static_cast<double>(std::abs(moved[s] - m.median)) >
                                  o.displacement_sigma * static_cast<double>(m.scale);
      };
      std::vector<double> rho(R, 0.0);
      std::vector<std::uint8_t> low_l(by_l ? R : 0, 0);
      const std::size_t anchors = by_d ? (R + kDisplacementAnchor - 1) / kDisplacementAnchor : 0;
      std::vector<MoveStats> anchor_stats(anchors);
      parallel_each(ridx.cell_count(), [&](std::size_t c) {
        for_cell(
            c, [](std::size_t) { return true; },
            [&](std::size_t s, const NearPoints& near) {
              const bool anchor = by_d && s % kDisplacementAnchor == 0;
              // Likelihood ratio: L_s < ratio x Q1, Q1 the element at rank floor(n / 4) of the
              // n likelihoods around, holds exactly when at most floor(n / 4) of them have
              // ratio x L_q <= L_s (ratio x L is monotone in L), so a count replaces the
              // selection. No points around (s is off the thinned subsample, and alone): Q1
              // would be L_s itself, kept.
              const double l_s = by_l ? static_cast<double>(lik[s]) : 0.0;
              float bound = 0;
              if (!anchor &&
                  (!by_l || largest_float_scaled_at_or_below(o.likelihood_ratio, l_s, bound))) {
                // Not an anchor: counted in one pass.
                const Eigen::Vector3f& q = ridx.slot_point(s);
                const float qa[3] = {q.x(), q.y(), q.z()};
                WithinCounts w;
                loops.count_within(near.x.data(), near.y.data(), near.z.data(), near.cnt.data(),
                                   by_l ? near.lik.data() : nullptr, near.n, qa, hs[s] * hs[s],
                                   bound, w);
                rho[s] = static_cast<double>(w.sum) * static_cast<double>(stride);
                if (by_l) low_l[s] = w.n > 0 && w.at_or_below <= w.n / 4 ? 1 : 0;
                return;
              }
              thread_local std::vector<std::uint32_t> hits;
              const std::size_t na = around(s, near, hits);
              std::uint64_t sum = 0;
              std::size_t at_or_below = 0;
              for (std::size_t k = 0; k < na; ++k) {
                const std::uint32_t a = hits[k];
                sum += around_cnt[a];
                if (by_l)
                  at_or_below +=
                      o.likelihood_ratio * static_cast<double>(around_lik[a]) <= l_s ? 1 : 0;
              }
              rho[s] = static_cast<double>(sum) * static_cast<double>(stride);
              if (by_l) low_l[s] = na > 0 && at_or_below <= na / 4 ? 1 : 0;
              if (anchor) anchor_stats[s / kDisplacementAnchor] = move_stats_of(s, hits.data(), na);
            });
      });
      // Screen: a point whose move lies within half the threshold of the median of an anchor
      // around it within h (2 robust deviations at the default 4; the four anchors nearest in
      // grid order) is kept; every other point gets the test with its own statistics. The
      // screen saves time (the statistics change slowly over h): at 1M points 5 % of them were
      // left to requery with the two nearest anchors, and against the test at every point it
      // kept 1 of the 4,792 points the latter dropped on the real bunny scans (6 with four).
      std::vector<std::uint8_t> displaced(by_d ? R : 0, 0), requery(by_d ? R : 0, 0);
      if (by_d) {
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
          requery[s] = 1;
        });
        // The points the screen left, cell by cell.
        parallel_each(ridx.cell_count(), [&](std::size_t c) {
          for_cell(
              c, [&](std::size_t s) { return requery[s] != 0; },
              [&](std::size_t s, const NearPoints& near) {
                displaced[s] = is_displaced(s, move_stats_at(s, near)) ? 1 : 0;
              });
        });
      }
      const double threshold = o.tau > 0 ? o.tau * median_of(rho) : 0.0;
      parallel_each(R, [&](std::size_t s) {
        if (rho[s] < threshold)
          drop[s] = Removal::kLowDensity;
        else if (by_l && low_l[s])
          drop[s] = Removal::kLowLikelihood;
        else if (by_d && displaced[s])
          drop[s] = Removal::kDisplaced;
      });
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
    parallel_each(R, [&](std::size_t s) { rep_drop[rord[s]] = drop[s]; });
  }

  return rep_drop;
}

}  // namespace scanclean::detail

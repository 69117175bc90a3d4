#include "scale.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <sstream>
#include <utility>

#include "cell_groups.h"
#include "kernel_fit.h"
#include "noise_scale.h"
#include "parallel.h"
#include "scale_selection.h"
#include "scanclean/core/errors.h"
#include "select.h"

namespace scanclean::detail {
namespace {

// kAdaptive looks for a point's K-th distance first in a band of +-3 % around the last one
// found in its cell, then in up to three bands of the same width on the side the count points
// to, around where the count extrapolates to K. Narrow bands keep the selection
// within them short; on the noisy 2.1M-point sphere of the speed suite +-3 % and four bands
// took the scale phase from 2.15 to 1.90 s against +-5 % and bands three times as wide.
constexpr float kGuessBand = 0.03f;
constexpr int kGuessAttempts = 4;
// The compact copy of a cell's octant holds the points within this factor times the last K-th
// distance found of the octant's bounding box.
constexpr float kGroupReach = 1.12f;

}  // namespace

ScaleChoice choose_scale(PointSet& in, const std::vector<Eigen::Vector3f>& pf, double diag,
                         bool use_sensor_normals, const FilterOptions& o) {
  ScaleChoice sr;
  const std::size_t N = pf.size();
  double h = 0;
  const int K = o.scale == ScaleMode::kAdaptive ? o.k_adaptive : o.k_h;
  const double fallback_h = diag > 0 ? 1e-3 * diag : 1e-3;
  std::unique_ptr<NeighborIndex> test_grid;  // the scale test's (NoiseScale::test_grid)
  if (o.scale == ScaleMode::kFixed) {
    h = o.h;
  } else {
    // A rough K-th neighbour distance from a k-d tree over a subsample (the (K+1)/step-th
    // neighbour among every step-th point), only to size the grid and the first query radius;
    // the distances used below are then exact, from grid radius queries.
    const std::size_t M = std::min<std::size_t>(N, 10000);
    std::vector<std::size_t> sample(M);
    for (std::size_t k = 0; k < M; ++k) sample[k] = k * N / M;
    const std::size_t kk = static_cast<std::size_t>(K) + 1;
    double r_est = rough_kth_distance(pf, kk, M);
    if (!(r_est > 0)) r_est = fallback_h;
    const float r_max = static_cast<float>(2 * diag + fallback_h);
    // kAdaptive queries every point, in the 27 cells around its own: cells of 1.5 r hold the
    // K-th neighbour of all but a few points of a noisy surface (on the 2.1M-point sphere of
    // the speed suite 3,195 took the general search, 94,208 with cells of 1.2 r) and the band
    // counts below keep the larger cells cheap.
    sr.index =
        std::make_unique<NeighborIndex>(pf, r_est * (o.scale == ScaleMode::kAdaptive ? 1.5 : 1.6));
    // Exact distance to the K-th other point: all points within r, grown until K + 1 found.
    // With a `reach`, the search stops before r would pass it (the grid's 27-cell radius; past
    // it a query takes the k-d tree, built over every point at the first such query) and
    // returns minus the last radius searched, below the K-th distance.
    auto kth = [&](const Eigen::Vector3f& q, float reach = 0) {
      thread_local std::vector<float> d2s;
      d2s.reserve(4 * kk);
      float r = static_cast<float>(r_est * 1.15);
      while (true) {
        d2s.clear();
        sr.index->for_each_within(q, r, [&](std::uint32_t, float d2) { d2s.push_back(d2); });
        if (d2s.size() >= kk)
          return std::sqrt(static_cast<double>(
              detail::kth_smallest_below(d2s.data(), d2s.size(), kk - 1, r * r)));
        if (r >= r_max)  // fewer than K + 1 points in all
          return d2s.empty()
                     ? 0.0
                     : std::sqrt(static_cast<double>(*std::max_element(d2s.begin(), d2s.end())));
        if (reach > 0 && r * 1.25f > reach) return -static_cast<double>(r);
        r *= 1.25f;
      }
    };
    if (o.scale == ScaleMode::kAuto) {
      // The median needs only the samples below it exactly. Sparse samples (a range scan's far
      // surfaces) whose K-th distance lies beyond the grid's reach stop there first; when the
      // median of the distances so bounded lies below every bound, no such sample can be at or
      // below it, and it is the exact median. Else they are searched to the end.
      std::vector<double> kd(M, 0.0);
      const float reach = sr.index->max_adjacent_radius();
      parallel_each(M, [&](std::size_t k) { kd[k] = kth(pf[sample[k]], reach); });
      double lowest_bound = std::numeric_limits<double>::infinity();
      for (const double v : kd)
        if (v < 0) lowest_bound = std::min(lowest_bound, -v);
      if (lowest_bound < std::numeric_limits<double>::infinity()) {
        std::vector<double> bounded = kd;
        for (double& v : bounded) v = std::abs(v);
        if (!(median_of(bounded) < lowest_bound))
          parallel_each(M, [&](std::size_t k) {
            if (kd[k] < 0) kd[k] = kth(pf[sample[k]]);
          });
        else
          kd = std::move(bounded);
      }
      double h0 = median_of(kd);
      if (!(h0 > 0)) h0 = fallback_h;  // at least K_h + 1 coincident points
      sr.h0 = h0;
      if (!grid_serves(sr.index->cell(), h0))
        sr.index = std::make_unique<NeighborIndex>(pf, grid_cell_for(h0));
      // Noise fixed point and scale test (noise_scale.h) over every 4th sampled point of large
      // clouds (2,500 fits per step; the median moves by about 1 %).
      const std::size_t sig_step = M >= 4000 ? 4 : 1;
      std::vector<std::size_t> sig_samples, queries;
      for (std::size_t k = 0; k < M / sig_step; ++k) sig_samples.push_back(sample[k * sig_step]);
      for (std::size_t k = 0; k < M; k += sig_step) queries.push_back(sample[k]);
      NoiseScale ns =
          noise_scale(in, pf, *sr.index, sig_samples, queries, h0, diag, use_sensor_normals, o);
      sr.noise_sigma_h0 = ns.noise_sigma_h0;
      sr.noise_sigma = ns.noise_sigma;
      sr.h_noise = ns.h_noise;
      sr.crease_samples = ns.crease_samples;
      h = ns.h;
      test_grid = std::move(ns.test_grid);
    } else {
      std::vector<float> hi(N);
      // Cell by cell: the points of the 27 cells around a cell are copied once into a compact
      // buffer, and each point of the cell takes its distances to them there (vectorised). A
      // point with fewer than K + 1 within the start radius falls back to kth().
      const std::vector<std::uint32_t>& ord = sr.index->order();
      const float r0 = std::min(static_cast<float>(r_est * 1.15), sr.index->max_adjacent_radius());
      const float r02 = r0 * r0;
      const float rmax2 = sr.index->max_adjacent_radius() * sr.index->max_adjacent_radius();
      if (sr.index->cell_count() == 0)  // no grid (cannot happen with a cell > 0; kept safe)
        parallel_each(N, [&](std::size_t i) { hi[i] = static_cast<float>(kth(pf[i])); });
      const detail::SelectLoops loops = detail::select_loops();  // dispatched once, called per run
      parallel_each_reporting(sr.index->cell_count(), o, "scale", [&](std::size_t c) {
        thread_local std::vector<float> bx, by, bz, hit, band, cx, cy, cz;
        struct Run {
          std::size_t b, e;
          Eigen::Vector3f lo, hi;  // bounding box of the run's points
        };
        thread_local std::vector<Run> runs;
        // The arrays only grow (resizing them down and up again zero-filled them per cell):
        // nb says how much of them this cell uses.
        std::size_t nb = 0;
        sr.index->for_each_adjacent_run(c, [&](std::uint32_t b, std::uint32_t e) { nb += e - b; });
        if (bx.size() < nb + kStoreSlack)
          for (auto* v : {&bx, &by, &bz, &hit, &band, &cx, &cy, &cz})
            v->resize(2 * nb + kStoreSlack);
        runs.clear();
        std::size_t k = 0;
        sr.index->for_each_adjacent_run(c, [&](std::uint32_t b, std::uint32_t e) {
          Run run{k, k, sr.index->slot_point(b), sr.index->slot_point(b)};
          for (std::uint32_t s = b; s < e; ++s, ++k) {
            const Eigen::Vector3f& p = sr.index->slot_point(s);
            bx[k] = p.x();
            by[k] = p.y();
            bz[k] = p.z();
            run.lo = run.lo.cwiseMin(p);
            run.hi = run.hi.cwiseMax(p);
          }
          run.e = k;
          runs.push_back(run);
        });
        const float reach = sr.index->max_adjacent_radius();
        // The K-th distance of the point in slot s, exact: bands (below) over the np points
        // (px, py, pz), which hold every point within `within` of it, else over the 27 cells'
        // runs, else the full selection.
        auto kth_at = [&](std::uint32_t s, float& guess, const float* px, const float* py,
                          const float* pz, std::size_t np, float within) {
          const Eigen::Vector3f& q = sr.index->slot_point(s);
          const float qx = q.x(), qy = q.y(), qz = q.z();
          // The squared distance from q to a run's box: a run at least r away is skipped.
          auto gap2 = [&](const Run& run) {
            return (run.lo - q)
                .cwiseMax(q - run.hi)
                .cwiseMax(Eigen::Vector3f::Zero())
                .squaredNorm();
          };
          // Neighbouring points have nearly the same K-th distance: count the distances below
          // a band around the last one found and keep those inside it. When the band holds
          // rank K, the K-th distance is selected among its few values; else the full search
          // below runs. Both give the exact K-th distance.
          if (guess > 0) {
            const float qa[3] = {qx, qy, qz};
            float lo = guess * (1 - kGuessBand), up = std::min(guess * (1 + kGuessBand), reach);
            for (int attempt = 0; attempt < kGuessAttempts && lo < up; ++attempt) {
              const float lo2 = lo * lo, up2 = up * up;
              std::size_t below = 0, m = 0;
              if (up <= within) {  // the compact points hold every point below up
                loops.count_below_and_band(px, py, pz, np, qa, lo2, up2, below, band.data(), m);
              } else {
                for (const Run& run : runs) {
                  if (!(gap2(run) < up2)) continue;
                  loops.count_below_and_band(bx.data() + run.b, by.data() + run.b,
                                             bz.data() + run.b, run.e - run.b, qa, lo2, up2, below,
                                             band.data(), m);
                }
              }
              if (below < kk && kk - 1 < below + m) {
                hi[ord[s]] = guess =
                    std::sqrt(kth_smallest_between(band.data(), m, kk - 1 - below, lo2, up2));
                return;
              }
              // The K-th distance lies below lo or at or above up: the next band, on that side,
              // goes around the distance at which the count would reach K were it to grow as
              // d^3 from the band's edge.
              const float kf = static_cast<float>(kk);
              if (below >= kk) {
                const float est = lo * std::cbrt(kf / static_cast<float>(below));
                up = std::min(lo, est * (1 + kGuessBand));
                lo = est * (1 - kGuessBand);
              } else {
                if (up >= reach) break;
                const std::size_t c = below + m;
                const float est =
                    c > 0 ? up * std::cbrt(kf / static_cast<float>(c)) : up * (1 + 3 * kGuessBand);
                lo = std::max(up, est * (1 - kGuessBand));
                up = std::min(est * (1 + kGuessBand), reach);
              }
            }
          }
          // All points within r of q when r <= max_adjacent_radius(); first the start radius,
          // then (rarely) the largest the 27 cells answer, then the general search.
          // (A band from 0: every distance below r2, in order.)
          auto select = [&](float r2) {
            const float qa[3] = {qx, qy, qz};
            std::size_t n = 0, below = 0;
            for (const Run& run : runs) {
              if (!(gap2(run) < r2)) continue;
              loops.count_below_and_band(bx.data() + run.b, by.data() + run.b, bz.data() + run.b,
                                         run.e - run.b, qa, 0.0f, r2, below, hit.data(), n);
            }
            return n;
          };
          float r2 = r02;
          std::size_t n = select(r2);
          if (n < kk) n = select(r2 = rmax2);
          if (n >= kk) {
            hi[ord[s]] = guess = std::sqrt(detail::kth_smallest_below(hit.data(), n, kk - 1, r2));
          } else {
            hi[ord[s]] = static_cast<float>(kth(q));
          }
        };
        // The cell's points in up to eight groups (octants about the centre of their bounding
        // box), each with a compact copy of the 27 cells' points within `within` of the group's
        // bounding box: within of the last K-th distance found, 12 % more, and at most the
        // grid's reach. A band below `within` counts those instead of the 27 cells (on a
        // surface about half as many), and gives the same count.
        const std::uint32_t cb = sr.index->cell_begin(c), ce = sr.index->cell_begin(c + 1);
        float guess = 0;  // the last distance found in this cell, 0 before the first
        kth_at(cb, guess, nullptr, nullptr, nullptr, 0, 0);
        if (ce - cb == 1) return;
        thread_local OctantGroups groups;
        group_by_octant(
            ce - cb - 1,
            [&](std::size_t k) -> const Eigen::Vector3f& {
              return sr.index->slot_point(cb + 1 + static_cast<std::uint32_t>(k));
            },
            groups);
        for (std::uint8_t g = 0; g < 8; ++g) {
          if (groups.members[g] == 0) continue;
          const Eigen::Vector3f& glo = groups.lo[g];
          const Eigen::Vector3f& ghi = groups.hi[g];
          const float within = std::min(guess * kGroupReach, reach);
          // A point's rounded squared distance to the box is at most its rounded squared
          // distance to any query in it (float rounding is monotone): the points below `within`
          // of a query are all kept; 0.1 % more to spare.
          const float w2 = within * within * 1.001f;
          std::size_t nc = 0;
          const float glo3[3] = {glo.x(), glo.y(), glo.z()}, ghi3[3] = {ghi.x(), ghi.y(), ghi.z()};
          for (const Run& run : runs) {
            const float g2 = (run.lo - ghi).cwiseMax(glo - run.hi).cwiseMax(0.0f).squaredNorm();
            if (g2 < w2)
              loops.select_near_box(bx.data() + run.b, by.data() + run.b, bz.data() + run.b,
                                    nullptr, nullptr, run.e - run.b, glo3, ghi3, w2,
                                    {cx.data(), cy.data(), cz.data()}, nc);
          }
          for (std::uint32_t s = cb + 1; s < ce; ++s)
            if (groups.octant[s - cb - 1] == g)
              kth_at(s, guess, cx.data(), cy.data(), cz.data(), nc, within);
        }
      });
      in.hi = std::move(hi);
      h = median_of(in.hi);
      if (!(h > 0)) h = fallback_h;
    }
  }
  in.h = h;
  sr.h = h;
  sr.h_grid = sr.h_grid_kernels = h;
  if (in.hi.empty()) {
    sr.h_min = sr.h_max = h;
  } else {  // kAdaptive, or a scale per region (scale_regions)
    const auto mm = std::minmax_element(in.hi.begin(), in.hi.end());
    sr.h_min = *mm.first;
    sr.h_max = *mm.second;
    const std::size_t last = in.hi.size() - 1;
    sr.h_grid = std::clamp(static_cast<double>(radix_select(in.hi, last * 99 / 100)), h, 1.7 * h);
    sr.h_grid_kernels =
        std::clamp(static_cast<double>(radix_select(in.hi, last * 999 / 1000)), sr.h_grid, 1.7 * h);
  }
  // The grid the later phases use: one that serves h_grid, else they build their own of
  // grid_cell_for(h_grid). The scale test's grid serves only when it is that very grid (h_grid is
  // its largest radius): a grid of other cells would move the thinned kernels' sites
  // (kernel_sites.h) and so the output.
  if (sr.index && !grid_serves(sr.index->cell(), sr.h_grid)) sr.index.reset();
  if (!sr.index && test_grid && test_grid->cell() == grid_cell_for(sr.h_grid))
    sr.index = std::move(test_grid);
  return sr;
}

void check_fixed_scale(const NeighborIndex& index, double h) {
  const std::size_t n = index.size(), cells = index.cell_count();
  if (n <= kMaxMedianNeighbours + 1) return;
  if (cells > 0 && index.max_adjacent_radius() >= h) {
    // Every point's neighbours lie in the 27 cells around its cell: if the median point's 27
    // cells hold few enough, so do its neighbourhoods.
    const std::size_t median = index.value_at_point_rank(index.adjacent_counts(), (n - 1) / 2);
    if (median <= kMaxMedianNeighbours + 1) return;
  }
  // Count exactly at 101 evenly spread points.
  constexpr std::size_t kSamples = 101;
  std::vector<std::size_t> count(kSamples, 0);
  const float r = static_cast<float>(h);
  parallel_each(kSamples, [&](std::size_t k) {
    const Eigen::Vector3f& q = index.slot_point(k * (n - 1) / (kSamples - 1));
    std::size_t c = 0;
    index.for_each_within(q, r, [&](std::uint32_t, float) { ++c; });
    count[k] = c > 0 ? c - 1 : 0;  // others
  });
  const std::size_t median = median_of(count);
  if (median > kMaxMedianNeighbours) {
    std::ostringstream msg;
    msg << "filter: h = " << h << " m puts a median of " << median
        << " other points within h of a point (of " << n << "); at most " << kMaxMedianNeighbours
        << " are supported, as the work grows with their number: give a smaller h (--h), or "
           "the automatic scale";
    throw OptionError(msg.str());
  }
}

}  // namespace scanclean::detail

#include "clustering.h"

#include <tbb/combinable.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <utility>

#include "fill_later.h"
#include "huge_pages.h"
#include "parallel.h"
#include "radix_sort.h"

namespace scanclean::detail {

Clusters cluster_points(const std::vector<Eigen::Vector3d>& x, const Projected& pr, double eps,
                        bool oriented) {
  const std::size_t n = x.size();
  Clusters cl;
  assign_huge(cl.rep_of, n, kNone);
  std::vector<std::uint32_t> cand =
      indices_where(n, [&](std::size_t i) { return projected(pr.state[i]); });
  if (!(eps > 0)) {
    for (std::uint32_t i : cand) {
      cl.rep_of[i] = static_cast<std::uint32_t>(cl.seed.size());
      cl.seed.push_back(i);
      cl.count.push_back(1);
      cl.position.push_back(x[i]);
    }
    return cl;
  }
  {
    // Decreasing L, then index (cand is in index order and the sort stable): deterministic.
    struct ByRank {  // trivial: the arrays are filled in parallel, not zeroed first
      std::uint32_t key, point;
    };
    FillLaterVector<ByRank> key(cand.size()), scratch;
    parallel_each(cand.size(), [&](std::size_t k) {
      key[k] = {float_order_key(-pr.L[cand[k]]), cand[k]};
    });
    stable_radix_sort(
        key, [](const ByRank& e) { return std::uint64_t{e.key}; }, scratch);
    parallel_each(cand.size(), [&](std::size_t k) { cand[k] = key[k].point; });
  }
  // The candidates' bounding box, in parallel (their positions are read in rank order, scattered).
  using Box = std::pair<Eigen::Vector3d, Eigen::Vector3d>;
  const Box empty{Eigen::Vector3d::Constant(std::numeric_limits<double>::max()),
                  Eigen::Vector3d::Constant(-std::numeric_limits<double>::max())};
  const auto [box_lo, box_hi] = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, cand.size(), kGrain), empty,
      [&](const tbb::blocked_range<std::size_t>& r, Box b) {
        for (std::size_t k = r.begin(); k < r.end(); ++k) {
          b.first = b.first.cwiseMin(x[cand[k]]);
          b.second = b.second.cwiseMax(x[cand[k]]);
        }
        return b;
      },
      [](const Box& a, const Box& b) {
        return Box{a.first.cwiseMin(b.first), a.second.cwiseMax(b.second)};
      });
  Eigen::Vector3d lo = box_lo, hi = box_hi;
  // Cells of 6 eps: a query box (2 eps a side) spans 1.33 cells per axis on average, 2.4 cells
  // in all instead of 8 with cells of 2 eps (fewer cells to visit; the same neighbours, as every
  // one is tested against eps). Measured at 1M points: the counting pass took half the time.
  double cell = 6 * eps;
  if (!cand.empty()) {
    const double extent = (hi - lo).maxCoeff();
    const double max_cells = (1 << 21) - 4;
    if (extent / cell > max_cells) cell = extent / max_cells * (1 + 1e-9);
    lo -= Eigen::Vector3d::Constant(cell);
  }
  // Any coordinate monotone in v finds every neighbour (the query box maps onto the cells
  // between its corners' cells): a product with 1 / cell, not a division.
  const double inv_cell = 1.0 / cell;
  auto coord = [&](double v, int a) {
    return static_cast<std::int32_t>(
        std::clamp(std::floor((v - lo[a]) * inv_cell), 0.0, static_cast<double>((1 << 21) - 1)));
  };
  // The greedy rule visits the candidates in rank order (decreasing L); candidate k becomes a
  // representative exactly when no earlier representative that accepts members lies within eps
  // of it (with agreeing normals): the lexicographically first maximal independent set of the
  // graph of such pairs. It is computed in parallel rounds (a candidate is decided once every
  // earlier neighbour is), then every other candidate joins its nearest earlier representative,
  // and the positions are summed in rank order: the same clusters, bit for bit, as one sequential
  // pass, for any thread count. Candidates that did not converge neither join nor accept.
  const std::size_t nc = cand.size();
  std::vector<std::uint8_t> joins(nc);
  parallel_each(nc, [&](std::size_t k) {
    joins[k] = pr.state[cand[k]] != ProjectionState::kNotConverged ? 1 : 0;
  });
  // Grid of the candidates that join: (cell, point index) sorted, their positions, normals and
  // ranks copied into that order. The cell is a dense number, x + nx (y + ny z), so that the
  // cells of one row along x are consecutive in that order. Built in point order (the filter's
  // grid order, so the positions are read in sequence).
  std::vector<std::uint32_t> rank_of;
  assign_huge(rank_of, n, kNone);
  parallel_each(nc, [&](std::size_t k) { rank_of[cand[k]] = static_cast<std::uint32_t>(k); });
  std::vector<std::uint32_t> joiners = indices_where(  // point indices, in point order
      n, [&](std::size_t i) { return rank_of[i] != kNone && joins[rank_of[i]] != 0; });
  const std::size_t nj = joiners.size();
  // Every cell coordinate lies in [0, top] (coord is monotone; lo is a cell below the box).
  std::int32_t top[3] = {0, 0, 0};
  if (!cand.empty())
    for (int a = 0; a < 3; ++a) top[a] = coord(hi[a], a);
  const std::uint64_t nx = static_cast<std::uint64_t>(top[0]) + 1,
                      nxy = nx * (static_cast<std::uint64_t>(top[1]) + 1);
  auto dense = [&](std::int32_t cx, std::int32_t cy, std::int32_t cz) {
    return static_cast<std::uint64_t>(cx) + nx * static_cast<std::uint64_t>(cy) +
           nxy * static_cast<std::uint64_t>(cz);
  };
  struct ByCell {  // trivial: the arrays are filled in parallel, not zeroed first
    std::uint64_t cell;
    std::uint32_t point;
  };
  FillLaterVector<ByCell> by_cell(nj);
  parallel_each(nj, [&](std::size_t j) {
    const Eigen::Vector3d& p = x[joiners[j]];
    by_cell[j] = {dense(coord(p[0], 0), coord(p[1], 1), coord(p[2], 2)), joiners[j]};
  });
  std::vector<std::uint32_t>().swap(joiners);
  {
    FillLaterVector<ByCell> scratch;
    stable_radix_sort(
        by_cell, [](const ByCell& e) { return e.cell; }, scratch);
  }
  std::vector<Eigen::Vector3d> cell_x;
  std::vector<Eigen::Vector3f> cell_n;
  resize_huge(cell_x, nj);
  resize_huge(cell_n, oriented ? nj : 0);
  FillLaterVector<std::uint32_t> cell_rank(nj);
  parallel_each(nj, [&](std::size_t j) {
    const std::uint32_t i = by_cell[j].point;
    cell_x[j] = x[i];
    if (oriented) cell_n[j] = pr.normal[i];
    cell_rank[j] = rank_of[i];
  });
  std::vector<std::uint32_t>().swap(rank_of);
  const double eps2 = eps * eps;
  // Visits the joining candidates by_cell[j], j in [j0, j1), in order, calling
  // f(j, k, for_each_earlier) (k: j's rank) with for_each_earlier(g) calling g(q) for the earlier
  // neighbours of j (rank q < its rank, within eps, normals agreeing). The query box [p - eps, p +
  // eps] meets at most two cells per axis (cells of 6 eps) and so up to four rows of cells along x;
  // each of the nine rows around j's cell has a cursor at the first entry of the cell before
  // j's, which only moves forward as j does (a galloping search), so no cell is looked up.
  auto sweep = [&](std::size_t j0, std::size_t j1, auto&& f) {
    std::array<std::size_t, 9> cursor;
    cursor.fill(j0);
    std::array<bool, 9> placed{};
    auto seek = [&](std::size_t r, std::uint64_t target) {
      std::size_t c = cursor[r];
      if (!placed[r]) {  // first use in this range: from the start
        c = static_cast<std::size_t>(
            std::lower_bound(by_cell.begin(), by_cell.end(), target,
                             [](const ByCell& e, std::uint64_t t) { return e.cell < t; }) -
            by_cell.begin());
        placed[r] = true;
      } else if (c < nj && by_cell[c].cell < target) {
        std::size_t step = 1, lo_c = c;
        while (c + step < nj && by_cell[c + step].cell < target) {
          lo_c = c + step;
          step *= 2;
        }
        c = static_cast<std::size_t>(
            std::lower_bound(by_cell.begin() + static_cast<std::ptrdiff_t>(lo_c),
                             by_cell.begin() + static_cast<std::ptrdiff_t>(std::min(c + step, nj)),
                             target, [](const ByCell& e, std::uint64_t t) { return e.cell < t; }) -
            by_cell.begin());
      }
      cursor[r] = c;
      return c;
    };
    for (std::size_t j = j0; j < j1; ++j) {
      const Eigen::Vector3d& p = cell_x[j];
      const std::uint32_t k = cell_rank[j];
      std::int32_t c3[3], a0[3], a1[3];
      for (int a = 0; a < 3; ++a) {
        c3[a] = coord(p[a], a);
        a0[a] = coord(p[a] - eps, a);
        a1[a] = std::min(coord(p[a] + eps, a), top[a]);
      }
      auto for_each_earlier = [&](auto&& g) {
        for (std::int32_t cz = a0[2]; cz <= a1[2]; ++cz)
          for (std::int32_t cy = a0[1]; cy <= a1[1]; ++cy) {
            const std::size_t r = static_cast<std::size_t>(3 * (cz - c3[2] + 1) + (cy - c3[1] + 1));
            const std::uint64_t first = dense(a0[0], cy, cz), last = dense(a1[0], cy, cz);
            for (std::size_t q = seek(r, dense(c3[0] - 1, cy, cz));
                 q < nj && by_cell[q].cell <= last; ++q) {
              if (by_cell[q].cell < first) continue;
              const std::uint32_t rq = cell_rank[q];
              if (rq >= k) continue;
              const double d2 = (cell_x[q] - p).squaredNorm();
              if (!(d2 < eps2)) continue;
              if (oriented && !(cell_n[q].dot(cell_n[j]) > 0)) continue;
              g(rq);
            }
          }
      };
      f(j, k, for_each_earlier);
    }
  };
  // One pass in grid order (spatially coherent): each thread keeps the (candidate, earlier
  // neighbour) pairs it finds, a candidate's all in one thread and in the sweep's order (few
  // candidates have any after the projection); then the rows are laid out by rank and filled
  // in that order, whichever thread found them.
  struct Pair {
    std::uint32_t k, q;
  };
  tbb::combinable<std::vector<Pair>> found;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nj, kGrain),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      std::vector<Pair>& mine = found.local();
                      sweep(range.begin(), range.end(),
                            [&](std::size_t, std::uint32_t k, auto&& for_each_earlier) {
                              for_each_earlier([&](std::uint32_t q) { mine.push_back({k, q}); });
                            });
                    });
  std::vector<std::uint32_t> row(nc + 1, 0);
  found.combine_each([&](const std::vector<Pair>& v) {
    for (const Pair& e : v) ++row[e.k + 1];
  });
  for (std::size_t k = 0; k < nc; ++k) row[k + 1] += row[k];
  std::vector<std::uint32_t> nb;
  resize_huge(nb, row[nc]);
  {
    std::vector<std::uint32_t> fill(row.begin(), row.end() - 1);
    found.combine_each([&](const std::vector<Pair>& v) {
      for (const Pair& e : v) nb[fill[e.k]++] = e.q;
    });
  }
  // Rounds: a candidate with an earlier representative among its neighbours is a member; one
  // whose earlier neighbours are all members is a representative.
  enum : std::uint8_t { kUndecided, kRep, kMember };
  std::vector<std::uint8_t> role(nc), next_role;
  parallel_each(
      nc, [&](std::size_t k) { role[k] = !joins[k] || row[k] == row[k + 1] ? kRep : kUndecided; });
  std::vector<std::uint32_t> open =
      indices_where(nc, [&](std::size_t k) { return role[k] == kUndecided; });
  auto decide = [&](std::uint32_t k, const std::vector<std::uint8_t>& from) {
    bool all_members = true;
    for (std::uint32_t m = row[k]; m < row[k + 1]; ++m) {
      if (from[nb[m]] == kRep) return kMember;
      all_members = all_members && from[nb[m]] == kMember;
    }
    return all_members ? kRep : kUndecided;
  };
  constexpr int kParallelRounds = 32;
  for (int round = 0; round < kParallelRounds && !open.empty(); ++round) {
    next_role = role;
    parallel_each(open.size(), [&](std::size_t u) { next_role[open[u]] = decide(open[u], role); });
    role.swap(next_role);
    std::vector<std::uint32_t> still;
    for (std::uint32_t k : open)
      if (role[k] == kUndecided) still.push_back(k);
    open.swap(still);
  }
  // Long chains of dependencies: the rest in rank order (each one's earlier neighbours are
  // decided by then).
  for (std::uint32_t k : open) role[k] = decide(k, role);
  // Representatives in rank order; members join the nearest earlier one (ties: the earlier).
  const std::vector<std::uint32_t> reps =
      indices_where(nc, [&](std::size_t k) { return role[k] == kRep; });
  const std::size_t R = reps.size();
  std::vector<std::uint32_t> rep_index;
  assign_huge(rep_index, nc, kNone);
  resize_huge(cl.seed, R);
  parallel_each(R, [&](std::size_t r) {
    rep_index[reps[r]] = static_cast<std::uint32_t>(r);
    cl.seed[r] = cand[reps[r]];
  });
  std::vector<std::uint32_t> joined;
  assign_huge(joined, nc, kNone);  // per candidate: its representative
  parallel_each(nc, [&](std::size_t k) {
    if (role[k] == kRep) {
      joined[k] = rep_index[k];
      return;
    }
    std::uint32_t best = kNone;
    double best_d2 = eps2;
    for (std::uint32_t m = row[k]; m < row[k + 1]; ++m) {
      const std::uint32_t r = rep_index[nb[m]];
      if (r == kNone) continue;
      // The sweep's squared distance (neighbour minus candidate, the same doubles).
      const double d2 = (x[cand[nb[m]]] - x[cand[k]]).squaredNorm();
      if (best == kNone || d2 < best_d2 || (d2 == best_d2 && r < best)) {
        best = r;
        best_d2 = d2;
      }
    }
    joined[k] = best;
  });
  // Members of each representative in rank order, then each representative's L-weighted sum in
  // that order. A representative comes first among its members (they join earlier ones); the
  // others (few: most points stay alone) follow it in rank order.
  const std::vector<std::uint32_t> joiners_k =
      indices_where(nc, [&](std::size_t k) { return role[k] != kRep; });
  std::vector<std::uint32_t> first(R + 1, 0), members;
  resize_huge(members, nc);
  parallel_each(R, [&](std::size_t r) { first[r + 1] = 1; });
  for (const std::uint32_t k : joiners_k) ++first[joined[k] + 1];
  for (std::size_t r = 0; r < R; ++r) first[r + 1] += first[r];
  parallel_each(R, [&](std::size_t r) { members[first[r]] = reps[r]; });
  {
    std::vector<std::uint32_t> fill(R);
    parallel_each(R, [&](std::size_t r) { fill[r] = first[r] + 1; });
    for (const std::uint32_t k : joiners_k) members[fill[joined[k]]++] = k;
  }
  resize_huge(cl.count, R);
  resize_huge(cl.position, R);
  parallel_each(R, [&](std::size_t r) {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    double l = 0;
    for (std::uint32_t m = first[r]; m < first[r + 1]; ++m) {
      const std::uint32_t i = cand[members[m]];
      const double li = std::max(0.0, static_cast<double>(pr.L[i]));
      if (m == first[r])
        sum = li * x[i];
      else
        sum += li * x[i];
      l += li;
      cl.rep_of[i] = static_cast<std::uint32_t>(r);
    }
    cl.count[r] = first[r + 1] - first[r];
    cl.position[r] = l > 0 ? Eigen::Vector3d(sum / l) : x[cl.seed[r]];
  });
  return cl;
}

}  // namespace scanclean::detail

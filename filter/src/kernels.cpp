#include "kernels.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <type_traits>

#include "cell_select.h"
#include "huge_pages.h"
#include "kernel_fit.h"
#include "parallel.h"
#include "plane_refit.h"

namespace scanclean::detail {

KernelSet build_kernels(const PointSet& d, std::unique_ptr<NeighborIndex>& point_index,
                        PointIndexIds ids, const KernelParams& prm,
                        std::vector<Eigen::Vector3f>& nref, const std::string& phase) {
  const NeighborIndex& idx = *point_index;
  const std::size_t n = d.p.size();
  const FilterOptions& o = *prm.options;
  const std::size_t stride = std::max<std::size_t>(1, prm.stride);
  // Kernel candidates: i = k stride, or the given sites (slot[i] = k).
  auto stride_at = [&](std::size_t i) {
    return prm.strides && !prm.sites ? std::size_t{(*prm.strides)[i]} : stride;
  };
  auto is_site = [&](std::size_t i) {
    return prm.sites ? (*prm.sites)[i] != 0 : i % stride_at(i) == 0;
  };
  std::vector<std::uint32_t> slot;
  std::size_t nk = (n + stride - 1) / stride;
  const bool listed = prm.sites || prm.strides;
  if (listed) {
    slot.resize(n);
    nk = 0;
    for (std::size_t i = 0; i < n; ++i) {
      slot[i] = static_cast<std::uint32_t>(nk);
      nk += is_site(i) ? 1 : 0;
    }
  }
  auto candidate = [&](std::size_t i) { return listed ? slot[i] : i / stride; };
  // The records and fits of the valid kernels are written by the parallel loop below (pages
  // first touched there, not zeroed by this thread); the others are never read.
  std::vector<std::uint8_t> valid(nk, 0);
  FillLaterVector<KernelRecord> records(nk);  // candidate order first
  FillLaterVector<KernelFitRecord> fits(prm.keep_fits ? nk : 0);
  resize_huge(nref, n);  // Eigen vectors: not initialised, zeroed in parallel
  parallel_each(n, [&](std::size_t i) { nref[i].setZero(); });
  const double floor2 = o.eigen_floor * o.eigen_floor;
  const bool by_slot = ids == PointIndexIds::kSlots;
  PlaneRefit refit;
  refit.sigma = prm.noise_sigma;
  refit.ratio = o.refit_spread;
  refit.crease_ratio = o.crease_spread;
  refit.k_min = o.k_min;
  refit.eigen_floor = o.eigen_floor;
  // Per kernel candidate: 1 refitted on its own sheet, 2 split at a crease.
  std::vector<std::uint8_t> refitted(refit.sheets() || refit.creases() ? nk : 0, 0);
  const std::uint64_t cell_key = new_cell_cache_key();
  parallel_each_reporting(n, o, phase, [&](std::size_t i) {
    // d is in grid order: a spatially even subsample
    if (!is_site(i)) return;
    const double h = d.hi_at(i);
    const Eigen::Vector3f qi =
        by_slot ? idx.slot_point(i) : idx.point(static_cast<std::uint32_t>(i));
    KernelFit fit;
    const float r = static_cast<float>(h * 1.0001);
    // f(neighbours): by slot through the cell cache, as an array (valid until the thread's
    // next cell query; the same slots in the same order as the index's query); by point id
    // through the index's query.
    auto with_neighbours = [&](auto&& f) {
      if (by_slot) {
        const auto [js, m] = thread_cell_select().slots_within(idx, cell_key, qi, r);
        return f(IndexSpan{js, m});
      }
      return f(
          [&](auto&& g) { idx.for_each_within(qi, r, [&](std::uint32_t j, float) { g(j); }); });
    };
    // With the sheet refit on, most kernels on noisy data ask for it: the neighbours are kept
    // untrimmed from the gather. The crease split alone first tests their unweighted moments
    // (bends_away) and gathers them again only where that passes (few kernels).
    thread_local std::vector<FitSample> gathered;
    SampleMoments moments;
    // With measured sensor normals the fits already leave out the neighbours facing away (the
    // other sheet of a thin part); a second layer facing the same way is the same surface seen
    // twice (scans registered a fraction of a millimetre apart), which the kernel should
    // average: no sheet refit. Normals that only orient (estimated, orient_k) can miss a thin
    // part's other sheet: the refit stays.
    const bool keep = refit.sheets() && !(prm.oriented && !d.v_orients_only);
    const bool ok = with_neighbours([&](auto&& neighbours) {
      return fit_kernel(d, i, h, o.k_min, prm.oriented, o.eigen_floor, neighbours, fit,
                        keep ? &gathered : nullptr, refit.creases() ? &moments : nullptr);
    });
    if (!ok) return;
    const bool use_dir = prm.oriented && d.has_v(i);
    std::uint8_t how = 0;
    if (wants_split(fit, refit) && bends_away(moments, fit)) {
      if (!keep) {
        thread_local FitSampleSet again;
        with_neighbours(
            [&](auto&& neighbours) { gather_samples(d, i, h, prm.oriented, neighbours, again); });
        gathered.clear();
        again.append_to(gathered);
      }
      if (split_crease(gathered, d.p[i], refit, fit)) how = 2;
    }
    if (how == 0 && keep && wants_refit(fit, refit) &&
        refit_own_plane(gathered, d.p[i], h, refit, fit))
      how = 1;
    if (how != 0) {
      refitted[candidate(i)] = how;
      fit.n =
          kernel_normal(fit, use_dir, d.v_orients_only, use_dir ? d.v[i] : Eigen::Vector3f::Zero());
    }
    nref[i] = fit.n;
    if (prm.support) (*prm.support)[i] = static_cast<float>(fit.weight - 1.0);
    if (!(d.w_at(i) > 0)) return;  // a zero-weight kernel contributes nothing
    const double h2 = h * h;
    Eigen::Vector3d var;
    for (int a = 0; a < 3; ++a) var[a] = std::max(fit.lambda[a], floor2 * h2);
    const Eigen::Matrix3d s_inv = fit.e * var.cwiseInverse().asDiagonal() * fit.e.transpose();
    const std::size_t k = candidate(i);
    records[k].set(fit.c, s_inv, fit.n, h2, d.w_at(i) * static_cast<float>(stride_at(i)),
                   std::sqrt(var.maxCoeff()));
    if (prm.keep_fits) fits[k].set(fit.m, fit.weight, fit.cov);
    valid[k] = 1;
  });
  point_index.reset();  // the point index is not needed any more (memory)
  std::vector<std::uint32_t>().swap(slot);
  KernelSet ks;
  ks.fitted = count_where(n, [&](std::size_t i) { return nref[i].squaredNorm() > 0; });
  for (std::uint8_t r : refitted) {
    ks.refitted += r == 1 ? 1 : 0;
    ks.split += r == 2 ? 1 : 0;
  }
  // The valid kernels, their centres indexed; then the records (and fits) into the index's
  // slot order. Thinned kernels (at most one point in two) are gathered in parallel into a new
  // array, one array at a time: the copy costs at most 32 bytes a point, and at k = 250 on the
  // 2.1M-point sphere of the speed suite (every 2nd point) the run's peak lies elsewhere. A
  // kernel at every point would raise the peak by 64 bytes a point: those are moved in place,
  // cycle by cycle (one thread; the moves' loads are scattered).
  const std::vector<std::uint32_t> kept =
      indices_where(nk, [&](std::size_t k) { return valid[k] != 0; });
  std::vector<std::uint8_t>().swap(valid);
  const std::size_t m = kept.size();
  std::vector<Eigen::Vector3f> centres(m);
  parallel_each(m, [&](std::size_t k) { centres[k] = records[kept[k]].centre(); });
  ks.index = std::make_unique<NeighborIndex>(
      std::move(centres),
      grid_cell_for((prm.kernel_cell > 0 ? prm.kernel_cell : prm.cell) * prm.gather_factor));
  const auto& order = ks.index->order();
  if (2 * m <= n) {
    auto gather = [&](auto& v) {
      std::remove_reference_t<decltype(v)> to(m);
      parallel_each(m, [&](std::size_t s) { to[s] = v[kept[order[s]]]; });
      v.swap(to);
    };
    gather(records);
    if (prm.keep_fits) gather(fits);
  } else {
    for (std::size_t k = 0; k < m; ++k) {  // compact: kept[k] >= k
      records[k] = records[kept[k]];
      if (prm.keep_fits) fits[k] = fits[kept[k]];
    }
    records.resize(m);
    if (prm.keep_fits) fits.resize(m);
    std::vector<bool> done(m, false);
    for (std::size_t s0 = 0; s0 < m; ++s0) {
      if (done[s0]) continue;
      const KernelRecord first = records[s0];
      const KernelFitRecord first_fit = prm.keep_fits ? fits[s0] : KernelFitRecord{};
      std::size_t s = s0;
      while (true) {
        done[s] = true;
        const std::size_t from = order[s];
        if (from == s0) {
          records[s] = first;
          if (prm.keep_fits) fits[s] = first_fit;
          break;
        }
        records[s] = records[from];
        if (prm.keep_fits) fits[s] = fits[from];
        s = from;
      }
    }
  }
  ks.records = std::move(records);
  ks.fits = std::move(fits);
  return ks;
}

}  // namespace scanclean::detail

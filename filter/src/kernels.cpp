#include "kernels.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "cell_select.h"
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
  std::vector<std::uint8_t> valid(nk, 0);
  std::vector<KernelRecord> records(nk);  // candidate order first
  std::vector<KernelFitRecord> fits(prm.keep_fits ? nk : 0);
  nref.assign(n, Eigen::Vector3f::Zero());
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
  for (std::size_t i = 0; i < n; ++i) ks.fitted += nref[i].squaredNorm() > 0 ? 1 : 0;
  for (std::uint8_t r : refitted) {
    ks.refitted += r == 1 ? 1 : 0;
    ks.split += r == 2 ? 1 : 0;
  }
  // Compact the valid kernels (in place, with their fits), index their centres, then permute
  // the records in place into the index's slot order, cycle by cycle (no second copy: memory).
  std::size_t m = 0;
  for (std::size_t k = 0; k < nk; ++k) {
    if (!valid[k]) continue;
    if (m != k) {
      records[m] = records[k];
      if (prm.keep_fits) fits[m] = fits[k];
    }
    ++m;
  }
  std::vector<std::uint8_t>().swap(valid);
  records.resize(m);
  if (prm.keep_fits) fits.resize(m);
  std::vector<Eigen::Vector3f> centres(m);
  for (std::size_t k = 0; k < m; ++k) centres[k] = records[k].centre();
  ks.index = std::make_unique<NeighborIndex>(
      std::move(centres),
      grid_cell_for((prm.kernel_cell > 0 ? prm.kernel_cell : prm.cell) * prm.gather_factor));
  const auto& order = ks.index->order();
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
  ks.records = std::move(records);
  ks.fits = std::move(fits);
  return ks;
}

}  // namespace scanclean::detail

#include "noise_scale.h"

#include <algorithm>
#include <cmath>

#include "kernel_fit.h"
#include "parallel.h"
#include "scale_selection.h"
#include "select.h"

namespace scanclean::detail {

double noise_start_radius(double h0, int k_h) {
  if (k_h >= kNoiseNeighbours || k_h <= 0) return h0;
  return h0 * std::sqrt(static_cast<double>(kNoiseNeighbours) / k_h);
}

NoiseScale noise_scale(PointSet& in, const std::vector<Eigen::Vector3f>& pf,
                       const NeighborIndex& index, const std::vector<std::size_t>& sigma_samples,
                       const std::vector<std::size_t>& test_samples, double h0, double diag,
                       bool use_sensor_normals, const FilterOptions& o) {
  NoiseScale ns;
  // Noise: median sqrt(lambda_3) of the PCA at scale hs over the samples. At hs below about
  // 6 sigma the window cuts the noise band and the estimate falls short of sigma (0.46 sigma at
  // hs = 2.4 sigma, measured), so h = max(h0, noise_factor sigma(h)) is solved as a fixed point
  // from hs = h0 upwards: hs grows while noise_factor sigma(hs) exceeds it, and the estimate
  // grows with it.
  // The points in the index's slot order (positions and sensor normals, what the fits read):
  // a fit's neighbours are then a few runs of consecutive slots instead of points scattered
  // over the cloud in input order. The same neighbours, in the same order.
  PointSet ds;
  ds.v_orients_only = in.v_orients_only;
  ds.p = permuted(in.p, index.order());
  if (!in.v.empty()) ds.v = permuted(in.v, index.order());
  auto sigma_at = [&](double hs) {
    ns.reach = std::max(ns.reach, hs * 1.0001);
    std::vector<double> sig(sigma_samples.size(), -1.0);
    in.h = hs;
    parallel_each(sig.size(), [&](std::size_t k) {
      KernelFit fit;
      const std::size_t i = sigma_samples[k];
      if (fit_kernel(
              ds, index.slot_of(static_cast<std::uint32_t>(i)), hs, o.k_min, use_sensor_normals,
              o.eigen_floor,
              [&](auto&& g) {
                index.for_each_slot_within(pf[i], static_cast<float>(hs * 1.0001),
                                           [&](std::uint32_t s, float) { g(s); });
              },
              fit))
        sig[k] = std::sqrt(fit.lambda[0]);
    });
    sig.erase(std::remove(sig.begin(), sig.end(), -1.0), sig.end());
    return median_of(sig);
  };
  const double start = noise_start_radius(h0, o.k_h);
  double hs = start;
  double sigma = sigma_at(hs);
  ns.noise_sigma_h0 = sigma;
  for (int step = 0; step < 8 && o.noise_factor * sigma > hs * 1.02 && hs < diag; ++step) {
    hs = o.noise_factor * sigma;
    sigma = sigma_at(hs);
  }
  ns.noise_sigma = sigma;
  double h = std::max(h0, o.noise_factor * ns.noise_sigma);
  ns.h_noise = h;
  if (o.scale_gamma > 0) {
    // The scale test (scale_selection.h) over the samples, on a grid sized for its largest
    // ball; h is the median radius chosen. The standard errors use the noise estimate
    // (trimmed, so clutter does not widen the intervals), floored like the kernels'
    // eigenvalues so that noise-free data keeps h near h_noise.
    ScaleSelectionOptions so;
    // Not below half the noise estimate's first radius (about 24 neighbours; a no-op at the
    // default K_h, where h / 2 >= h0 / 2): with K_h = 32 the test took h0 / 2, which holds about
    // 8 points, fewer than a kernel needs (k_min), and left most points without support.
    const double lowest = std::min(h, start / 2);
    for (int k = -4; k <= 2; ++k)
      if (const double r = h * std::pow(2.0, k / 4.0); r >= lowest) so.radii.push_back(r);
    so.gamma = o.scale_gamma;
    so.k_min = o.k_min;
    so.sigma = std::max(ns.noise_sigma, o.eigen_floor * h);
    // The crease test only with a scale per region: with one h for the cloud, the median
    // radius decides h everywhere, and raising it for the samples beside creases raised it for
    // thin parts and fine detail elsewhere too (the benchmark's thin plate at 50k points and
    // 2-3 % noise: CD 16-20 % worse; the bunny mesh at 10k / 3 %: 6 % worse).
    so.crease.sigma = so.sigma;
    so.crease.crease_ratio = o.scale_regions > 0 ? o.crease_spread : 0;
    so.crease.k_min = o.k_min;
    so.crease.eigen_floor = o.eigen_floor;
    ns.reach = std::max(ns.reach, so.radii.back() * 1.0001);
    ns.test_grid = std::make_unique<NeighborIndex>(pf, grid_cell_for(so.radii.back()));
    const std::vector<double> radii =
        select_scale(in.p, *ns.test_grid, test_samples, so, &ns.crease_samples);
    h = median_of(radii);
    if (o.scale_regions > 0) {
      // A scale per region: each point's h_i from the radii chosen nearest to its cell of
      // `index` (cells of h0), h their median (the later grids are sized for the h_i:
      // ScaleChoice::h_grid).
      std::vector<Eigen::Vector3f> at;
      at.reserve(test_samples.size());
      for (std::size_t q : test_samples) at.push_back(pf[q]);
      in.hi = region_scales(index, std::move(at), radii, static_cast<std::size_t>(o.scale_regions));
      h = median_of(in.hi);
    }
  }
  ns.h = h;
  return ns;
}

}  // namespace scanclean::detail

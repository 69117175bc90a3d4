#include "tile_scale.h"

#include <algorithm>
#include <cmath>

#include "kernel_fit.h"
#include "neighbor_index.h"
#include "parallel.h"
#include "scale_selection.h"
#include "select.h"

namespace scanclean::detail {

double kth_distance(std::vector<float>& d2, int K, float reach, bool all) {
  const std::size_t kk = static_cast<std::size_t>(K) + 1;
  if (d2.size() >= kk)
    return std::sqrt(
        static_cast<double>(kth_smallest_below(d2.data(), d2.size(), kk - 1, reach * reach)));
  if (!all) return -1;
  return d2.empty() ? 0.0 : std::sqrt(static_cast<double>(*std::max_element(d2.begin(), d2.end())));
}

TileScale scale_from_neighbourhoods(PointSet& g, const std::vector<std::size_t>& samples, double h0,
                                    double diag, bool use_sensor_normals, const FilterOptions& o) {
  TileScale ts;
  std::vector<Eigen::Vector3f> pf(g.p.size());
  parallel_each(g.p.size(), [&](std::size_t i) { pf[i] = g.p[i].cast<float>(); });
  const NeighborIndex index(pf, h0 * 1.001);
  // The same sampling as scale.h: sigma over samples[k], the scale test over samples[k] (the
  // caller passes the samples scale.h takes, every 4th at 4,000 and more).
  auto sigma_at = [&](double hs) {
    ts.reach = std::max(ts.reach, hs * 1.0001);
    std::vector<double> sig(samples.size(), -1.0);
    g.h = hs;
    parallel_each(sig.size(), [&](std::size_t k) {
      KernelFit fit;
      const std::size_t i = samples[k];
      if (fit_kernel(
              g, i, hs, o.k_min, use_sensor_normals, o.eigen_floor,
              [&](auto&& f) {
                index.for_each_within(pf[i], static_cast<float>(hs * 1.0001),
                                      [&](std::uint32_t j, float) { f(j); });
              },
              fit))
        sig[k] = std::sqrt(fit.lambda[0]);
    });
    sig.erase(std::remove(sig.begin(), sig.end(), -1.0), sig.end());
    return median_of(sig);
  };
  double hs = h0;
  double sigma = sigma_at(hs);
  ts.noise_sigma_h0 = sigma;
  for (int step = 0; step < 8 && o.noise_factor * sigma > hs * 1.02 && hs < diag; ++step) {
    hs = o.noise_factor * sigma;
    sigma = sigma_at(hs);
  }
  ts.noise_sigma = sigma;
  double h = std::max(h0, o.noise_factor * sigma);
  ts.h_noise = h;
  if (o.scale_gamma > 0) {
    ScaleSelectionOptions so;
    for (int k = -4; k <= 2; ++k) so.radii.push_back(h * std::pow(2.0, k / 4.0));
    so.gamma = o.scale_gamma;
    so.k_min = o.k_min;
    so.sigma = std::max(ts.noise_sigma, o.eigen_floor * h);
    ts.reach = std::max(ts.reach, so.radii.back() * 1.0001);
    const NeighborIndex wide(pf, so.radii.back() * 0.7);
    h = median_of(select_scale(g.p, wide, samples, so));
  }
  ts.h = h;
  return ts;
}

}  // namespace scanclean::detail

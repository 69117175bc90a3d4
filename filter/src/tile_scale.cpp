#include "tile_scale.h"

#include <algorithm>
#include <cmath>

#include "neighbor_index.h"
#include "parallel.h"
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

TileScale scale_from_neighbourhoods(PointSet& g, const std::vector<std::size_t>& sigma_samples,
                                    const std::vector<std::size_t>& test_samples, double h0,
                                    double diag, bool use_sensor_normals, const FilterOptions& o) {
  std::vector<Eigen::Vector3f> pf(g.p.size());
  parallel_each(g.p.size(), [&](std::size_t i) { pf[i] = g.p[i].cast<float>(); });
  const NeighborIndex index(pf, grid_cell_for(h0));
  return noise_scale(g, pf, index, sigma_samples, test_samples, h0, diag, use_sensor_normals, o);
}

}  // namespace scanclean::detail

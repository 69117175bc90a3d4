#pragma once
//! Internal: the last steps of the automatic h (FilterOptions::scale == kAuto), shared by the
//! in-memory scale phase (scale.h) and the tiled filter's first pass (tile_scale.h): the noise
//! sigma as a fixed point h = max(h0, noise_factor x sigma(h)) solved from h0 upwards, then the
//! scale test (scale_selection.h). Both callers pass the same sample points; the in-memory one
//! over the whole cloud, the tiled one over the gathered neighbourhoods of the samples.

#include <Eigen/Core>
#include <cstddef>
#include <memory>
#include <vector>

#include "neighbor_index.h"
#include "point_set.h"
#include "scanclean/filter/filter_options.h"

namespace scanclean::detail {

//! The fewest neighbours the noise estimate starts from. A plane fitted to few noisy points
//! follows their noise, and a window narrower than the noise band cuts it: both bias
//! sqrt(lambda_3) low. With K_h = 32 on the 1M-point speed sphere (h0 = 1.5 sigma) the estimate
//! at h0 was a quarter of sigma, noise_factor times it stayed below h0, so the fixed point
//! stopped there; the scale test then halved h and 97 % of the points were left without support
//! (28,249 out; a 50k-point sphere at 3.3 % noise: 1,796). Starting from about 96 neighbours (the
//! default K_h) the estimate grows out of it.
constexpr int kNoiseNeighbours = 96;
//! The radius the noise fixed point starts from: h0 (the median K_h-th neighbour distance), or
//! where K_h < kNoiseNeighbours, h0 sqrt(kNoiseNeighbours / K_h), about the radius that holds
//! kNoiseNeighbours points on a surface. The same h0 at the default K_h.
double noise_start_radius(double h0, int k_h);

struct NoiseScale {
  double h = 0;            //!< the automatic h (after the scale test when it is on)
  double noise_sigma = 0;  //!< median sqrt(lambda_3) at h_noise
  //! the same at the radius the fixed point starts from (noise_start_radius: h0 at the default
  //! K_h)
  double noise_sigma_h0 = 0;
  double h_noise = 0;  //!< max(h0, noise_factor sigma), before the scale test
  double reach = 0;    //!< the largest query radius used around a sample
  //! the scale test's samples whose radius its crease test raised (ScaleSelectionOptions::crease)
  std::size_t crease_samples = 0;
  //! The scale test's grid over every point of pf: cells of 1.001 x its largest radius, the
  //! cells the later phases want when h comes out at that radius (then they take it instead of
  //! building the same grid again). Null without the scale test.
  std::unique_ptr<NeighborIndex> test_grid;
};

//! The noise fixed point over `sigma_samples` and the scale test over `test_samples` (indices
//! into `in`, whose float copies relative to the same origin are `pf`, indexed by `index`);
//! `diag`: the cloud's bounding-box diagonal. Sets in.h on the way. Deterministic, parallel.
NoiseScale noise_scale(PointSet& in, const std::vector<Eigen::Vector3f>& pf,
                       const NeighborIndex& index, const std::vector<std::size_t>& sigma_samples,
                       const std::vector<std::size_t>& test_samples, double h0, double diag,
                       bool use_sensor_normals, const FilterOptions& o);

}  // namespace scanclean::detail

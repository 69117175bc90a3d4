#pragma once
//! Internal: the last steps of the automatic h (FilterOptions::scale == kAuto), shared by the
//! in-memory scale phase (scale.h) and the tiled filter's first pass (tile_scale.h): the noise
//! sigma as a fixed point h = max(h0, noise_factor x sigma(h)) solved from h0 upwards, then the
//! scale test (scale_selection.h). Both callers pass the same sample points; the in-memory one
//! over the whole cloud, the tiled one over the gathered neighbourhoods of the samples.

#include <Eigen/Core>
#include <cstddef>
#include <vector>

#include "neighbor_index.h"
#include "point_set.h"
#include "scanclean/filter/filter_options.h"

namespace scanclean::detail {

struct NoiseScale {
  double h = 0;               //!< the automatic h (after the scale test when it is on)
  double noise_sigma = 0;     //!< median sqrt(lambda_3) at h_noise
  double noise_sigma_h0 = 0;  //!< the same at h0
  double h_noise = 0;         //!< max(h0, noise_factor sigma), before the scale test
  double reach = 0;           //!< the largest query radius used around a sample
};

//! The noise fixed point over `sigma_samples` and the scale test over `test_samples` (indices
//! into `in`, whose float copies relative to the same origin are `pf`, indexed by `index`);
//! `diag`: the cloud's bounding-box diagonal. Sets in.h on the way. Deterministic, parallel.
NoiseScale noise_scale(PointSet& in, const std::vector<Eigen::Vector3f>& pf,
                       const NeighborIndex& index, const std::vector<std::size_t>& sigma_samples,
                       const std::vector<std::size_t>& test_samples, double h0, double diag,
                       bool use_sensor_normals, const FilterOptions& o);

}  // namespace scanclean::detail

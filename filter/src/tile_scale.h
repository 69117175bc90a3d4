#pragma once
//! Internal: the automatic h of the tiled filter (tiled_filter.h), from the neighbourhoods of the
//! cloud's sample points gathered in passes over the input, computed the way scale.h computes it
//! on the whole cloud: h0 = the median K_h-th neighbour distance over the sample, the noise
//! fixed point over every 4th sample (at 4,000 samples and more), then the scale test.

#include <Eigen/Core>
#include <cstddef>
#include <vector>

#include "point_set.h"
#include "scanclean/filter/filter_options.h"

namespace scanclean::detail {

//! The K-th neighbour distance from the squared float distances `d2` of one sample to the points
//! within `reach` (itself included); -1 when fewer than K + 1 lie within reach and `all` is
//! false (the reach must grow); with `all` (every point of the cloud is within reach), the
//! largest distance, as scale.h does for clouds of at most K points.
double kth_distance(std::vector<float>& d2, int K, float reach, bool all);

struct TileScale {
  double h = 0, noise_sigma = 0, noise_sigma_h0 = 0, h_noise = 0;
  double reach = 0;  //!< the largest query radius used: the gathered points must cover it
};

//! The noise fixed point and the scale test (scale.h) on the gathered points `g` (positions
//! relative to the cloud's origin, sensor normals and weights; every point within the reach of
//! every sample in `samples`, which index g). `every4`: the samples are every 4th of the
//! cloud's (scale.h's step at 4,000 samples and more); `diag`: the cloud's bounding-box diagonal.
TileScale scale_from_neighbourhoods(PointSet& g, const std::vector<std::size_t>& samples, double h0,
                                    double diag, bool use_sensor_normals, const FilterOptions& o);

}  // namespace scanclean::detail

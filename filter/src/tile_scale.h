#pragma once
//! Internal: the automatic h of the tiled filter (tiled_filter.h), from the neighbourhoods of the
//! cloud's sample points gathered in passes over the input, computed the way scale.h computes it
//! on the whole cloud: h0 = the median K_h-th neighbour distance over the sample, the noise
//! fixed point over every 4th sample (at 4,000 samples and more), then the scale test.

#include <Eigen/Core>
#include <cstddef>
#include <vector>

#include "noise_scale.h"
#include "point_set.h"
#include "scanclean/filter/filter_options.h"

namespace scanclean::detail {

//! The K-th neighbour distance from the squared float distances `d2` of one sample to the points
//! within `reach` (itself included); -1 when fewer than K + 1 lie within reach and `all` is
//! false (the reach must grow); with `all` (every point of the cloud is within reach), the
//! largest distance, as scale.h does for clouds of at most K points.
double kth_distance(std::vector<float>& d2, int K, float reach, bool all);

//! The automatic h from the gathered neighbourhoods (noise_scale.h; reach: the largest query
//! radius used around a sample, which the gathered points must cover).
using TileScale = NoiseScale;

//! The noise fixed point over `sigma_samples` and the scale test over `test_samples`
//! (noise_scale.h) on the gathered points `g` (positions relative to the cloud's origin, sensor
//! normals and weights; every point within the reach of every sample, which index g): the same
//! function and the same samples as the in-memory scale phase (scale.h); `diag`: the cloud's
//! bounding-box diagonal.
TileScale scale_from_neighbourhoods(PointSet& g, const std::vector<std::size_t>& sigma_samples,
                                    const std::vector<std::size_t>& test_samples, double h0,
                                    double diag, bool use_sensor_normals, const FilterOptions& o);

}  // namespace scanclean::detail

#pragma once
//! Internal: the outputs phase. Turns the representatives that passed the outlier tests into
//! the filtered cloud (in the input order of their seeds, with the filter's attributes), and
//! every dropped input point into the outlier cloud, and counts what happened in the stats.

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "clustering.h"
#include "outlier_tests.h"
#include "projection.h"
#include "scanclean/filter/robust_filter.h"

namespace scanclean::detail {

struct OutputInput {
  const PointCloud* input = nullptr;
  const Clusters* clusters = nullptr;
  const std::vector<Removal>* removal = nullptr;            //!< per representative
  const Projected* projected = nullptr;                     //!< per point (grid order)
  const std::vector<std::uint32_t>* input_index = nullptr;  //!< per point: its input index
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();         //!< added back to the positions
  //! Optional, per input point: how many input points it stands for (coincident points merged
  //! before filtering, input_groups.h); merge counts and the statistics count them all.
  const std::vector<std::uint32_t>* multiplicity = nullptr;
};

//! Fills result.cloud and result.outliers (robust_filter.h documents both) and the counts of
//! result.stats (points_out, merged, unsupported, off_surface, low_density, low_likelihood,
//! displaced, small_components).
void write_outputs(const OutputInput& in, FilterResult& result);

}  // namespace scanclean::detail

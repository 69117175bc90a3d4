#pragma once
//! Internal: what the filter does with two kinds of input that would otherwise break it, before
//! its phases run (robust_filter.cpp):
//!  - Coincident points (the same position exactly, as merged scans and repeated frames give):
//!    the phases run on one point per position, so that copies neither shrink the automatic scale
//!    (the k-th neighbour rank would count them) nor cost quadratic time (every copy is every
//!    other's neighbour). The point kept is the copy that comes first in the input; the others
//!    follow its fate: merged into the same output point, or removed with it.
//!  - Far points (stray returns kilometres away, or at 1e25 m): the phases work in float relative
//!    to a local origin on a grid of at most 2^21 cells a side, which one far point would stretch
//!    until the real data fall into one cell and lose their precision. The points far outside the
//!    bulk of the cloud (the box of its 1st to 99th percentiles, grown by four times its size on
//!    every side) are filtered as a group of their own, with the same options, and the results
//!    merged; within that group the rule applies again.

#include <cstddef>
#include <cstdint>
#include <vector>

#include "scanclean/core/point_cloud.h"
#include "scanclean/filter/robust_filter.h"

namespace scanclean::detail {

//! The groups of coincident points; all empty when every position is distinct.
struct Coincident {
  std::vector<std::size_t> first;       //!< per distinct position: its first input index
  std::vector<std::uint32_t> group_of;  //!< per input point: its position's index in first
  std::vector<std::uint32_t> count;     //!< per distinct position: the input points there
  bool any() const { return !first.empty(); }
};

//! Groups the input points by exact position (bitwise equal coordinates; +0 and -0 are equal).
//! Deterministic; a stable radix sort of position hashes.
Coincident find_coincident(const PointCloud& input);

//! The indices of the bulk (near) and of the far points (increasing). far is empty when no point
//! lies outside the grown percentile box, and when none lies inside it (then there is no bulk:
//! all points are near), so that far is always smaller than the input.
struct FarSplit {
  std::vector<std::size_t> near, far;
};
FarSplit split_far_points(const PointCloud& input);

//! The result for `input` from `distinct`, the result for select(input, c.first): output points
//! take their seeds' input indices, and every coincident copy of a removed point is removed with
//! it (same flags). Merge counts and statistics already count the copies (multiplicity).
void expand_coincident(const PointCloud& input, const Coincident& c, FilterResult& distinct);

//! Merges the results of the parts of a split (each with the input indices of its points, into
//! the whole): clouds and outliers in the input order of their source indices, counts summed,
//! the scale statistics of the first part (the bulk).
FilterResult merge_parts(std::vector<FilterResult> parts,
                         const std::vector<std::vector<std::size_t>>& indices);

}  // namespace scanclean::detail

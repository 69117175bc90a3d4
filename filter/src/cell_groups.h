#pragma once
//! Internal: the queries of one grid cell in up to eight groups, the octants about the centre of
//! their bounding box. The queries of a group share a compact copy of the points near the
//! group's box, which on a surface holds about half the points of the cell's 27-cell
//! neighbourhood: the adaptive scale's K-th distances (scale.cpp) and the outlier tests' counts
//! around the representatives (outlier_tests.cpp) scan those instead.

#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

namespace scanclean::detail {

struct OctantGroups {
  //! Per group, the bounding box of its points and their number (0: an empty group, box
  //! undefined).
  std::array<Eigen::Vector3f, 8> lo, hi;
  std::array<std::uint32_t, 8> members{};
  //! Per query k, its group.
  std::vector<std::uint8_t> octant;
};

//! Groups the n points p(k), k < n (n > 0), by octant about the centre of their bounding box
//! (bit a set for the upper half along axis a).
template <class P>
void group_by_octant(std::size_t n, P&& p, OctantGroups& g) {
  Eigen::Vector3f lo = p(0), hi = lo;
  for (std::size_t k = 1; k < n; ++k) {
    lo = lo.cwiseMin(p(k));
    hi = hi.cwiseMax(p(k));
  }
  const Eigen::Vector3f mid = 0.5f * (lo + hi);
  g.octant.resize(n);
  g.members.fill(0);
  g.lo.fill(Eigen::Vector3f::Constant(std::numeric_limits<float>::max()));
  g.hi.fill(Eigen::Vector3f::Constant(-std::numeric_limits<float>::max()));
  for (std::size_t k = 0; k < n; ++k) {
    const Eigen::Vector3f& q = p(k);
    const auto o = static_cast<std::uint8_t>(
        (q.x() >= mid.x() ? 1 : 0) | (q.y() >= mid.y() ? 2 : 0) | (q.z() >= mid.z() ? 4 : 0));
    g.octant[k] = o;
    g.lo[o] = g.lo[o].cwiseMin(q);
    g.hi[o] = g.hi[o].cwiseMax(q);
    ++g.members[o];
  }
}

}  // namespace scanclean::detail

#pragma once
//! Internal: the clustering phase (the paper's section 2, "clustering"). Projected points that
//! converged to the same maximum are merged greedily, in decreasing likelihood: each point joins
//! the nearest representative within merge_eps (with agreeing normals when oriented), or becomes
//! a representative itself.

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "projection.h"

namespace scanclean::detail {

struct Clusters {
  std::vector<std::uint32_t> seed;        //!< per representative: its seed's point index
  std::vector<std::uint32_t> count;       //!< per representative: its members
  std::vector<Eigen::Vector3d> position;  //!< per representative: L-weighted mean of members
  std::vector<std::uint32_t> rep_of;      //!< per point: its representative, or kNone
};

//! Clusters the projected points x (states and likelihoods in pr). Points not projected get no
//! representative; points that did not converge are representatives of their own (they neither
//! join nor accept others). Candidates are visited by decreasing L, ties by index; a point joins
//! the representative nearest to it (ties: the earlier one) among those closer than eps, whose
//! normal agrees with its own (dot > 0) when `oriented`. eps <= 0: every projected point is a
//! representative. Deterministic.
Clusters cluster_points(const std::vector<Eigen::Vector3d>& x, const Projected& pr, double eps,
                        bool oriented);

}  // namespace scanclean::detail

#pragma once
//! Internal: the points one pass of the filter works on, with their optional sensor normals,
//! weights and per-point kernel sizes, relative to the cloud's local origin.

#include <Eigen/Core>
#include <cstddef>
#include <vector>

namespace scanclean::detail {

struct PointSet {
  std::vector<Eigen::Vector3d> p;  //!< positions (metres, relative to the local origin)
  std::vector<Eigen::Vector3f> v;  //!< unit sensor normals (zero = none); empty = none
  std::vector<float> w;            //!< weights w_i; empty = all 1
  std::vector<float> hi;           //!< per-point kernel size h_i; empty = the fixed h
  double h = 0;                    //!< the kernel size when hi is empty
  //! v only selects a kernel's neighbours and orients its normal, which is then the PCA normal
  //! (FilterOptions::normals_orient_only); false: v is the kernel's normal.
  bool v_orients_only = false;
  double hi_at(std::size_t i) const { return hi.empty() ? h : static_cast<double>(hi[i]); }
  bool has_v(std::size_t i) const { return !v.empty() && v[i].squaredNorm() > 0.5f; }
  float w_at(std::size_t i) const { return w.empty() ? 1.0f : w[i]; }
};

}  // namespace scanclean::detail

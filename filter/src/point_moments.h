#pragma once
//! Internal: the unweighted moments of a set of points (every point counted once), summed in
//! double in the order the points are added: their count, the sums of the coordinates and of
//! their products (xx yy zz xy xz yz; the matrix is symmetric). The scale test sums them per
//! shell (scale_selection.cpp), the crease split per side of its wedge (plane_refit.cpp).

#include <Eigen/Core>

namespace scanclean::detail {

struct PointMoments {
  double n = 0;
  double s[3] = {0, 0, 0};
  double ss[6] = {0, 0, 0, 0, 0, 0};
  void add(double x, double y, double z) {
    n += 1;
    s[0] += x;
    s[1] += y;
    s[2] += z;
    ss[0] += x * x;
    ss[1] += y * y;
    ss[2] += z * z;
    ss[3] += x * y;
    ss[4] += x * z;
    ss[5] += y * z;
  }
  PointMoments& operator+=(const PointMoments& o) {
    n += o.n;
    for (int a = 0; a < 3; ++a) s[a] += o.s[a];
    for (int a = 0; a < 6; ++a) ss[a] += o.ss[a];
    return *this;
  }
  Eigen::Vector3d mean() const { return Eigen::Vector3d(s[0], s[1], s[2]) / n; }
  //! The mean of the products (x x^T).
  Eigen::Matrix3d second() const {
    Eigen::Matrix3d m;
    m << ss[0], ss[3], ss[4], ss[3], ss[1], ss[5], ss[4], ss[5], ss[2];
    return m / n;
  }
};

}  // namespace scanclean::detail

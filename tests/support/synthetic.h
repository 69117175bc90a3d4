#pragma once
//! Named, seeded synthetic fixtures (STYLE.md practice 14). Every generator takes an explicit
//! seed so that each test is reproducible run after run.

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "scanclean/core/point_cloud.h"
#include "scanclean/core/range_frame.h"

namespace scanclean::test {

//! One point's x, y and z from three draws made z first, then y, then x. C++ leaves the order
//! of a call's arguments to the compiler: gcc takes them last to first, clang first to last, so
//! `Eigen::Vector3d(u(rng), u(rng), z(rng))` is another point under clang, and some tests'
//! clouds were other clouds there. Written out in gcc's order, the clouds the tests were tuned
//! on stay the same, under any compiler.
template <class Rng, class DX, class DY, class DZ>
Eigen::Vector3d draw_point(Rng& rng, DX& dx, DY& dy, DZ& dz) {
  const double z = dz(rng);
  const double y = dy(rng);
  const double x = dx(rng);
  return {x, y, z};
}

//! n points uniform on the square [-size/2, size/2]^2 in the plane z = 0, with Gaussian noise of
//! standard deviation sigma along z. Normals (0,0,1).
PointCloud noisy_plane(std::size_t n, double size, double sigma, std::uint32_t seed);

//! n points uniform on a sphere of the given radius about the origin, with isotropic Gaussian
//! noise of standard deviation sigma. Outward normals of the clean surface.
PointCloud noisy_sphere(std::size_t n, double radius, double sigma, std::uint32_t seed);

//! Appends `count` points uniform in the box [lo, hi]^3 to `cloud` (normals, if present, get
//! random unit vectors). Returns the indices of the added points.
std::vector<std::size_t> add_uniform_outliers(PointCloud& cloud, std::size_t count, double lo,
                                              double hi, std::uint32_t seed);

//! Appends `count` points at distances in [near, far] from the sphere of the given radius about
//! the origin (uniform directions, alternately outside and inside) to a cloud without normals
//! or confidences: outliers close to the surface. Returns the indices of the added points.
std::vector<std::size_t> add_shell_outliers(PointCloud& cloud, std::size_t count, double radius,
                                            double near, double far, std::uint32_t seed);

//! An 8x6 depth frame of a wall at depth_mm (millimetre units, fx = fy = 10 px, centred) with a
//! colour image whose pixel (u, v) is (red, 10 u, 10 v).
RangeFrame coloured_wall_frame(std::uint16_t depth_mm, std::uint8_t red);

}  // namespace scanclean::test

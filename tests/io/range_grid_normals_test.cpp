#include "scanclean/io/range_grid_normals.h"

#include <gtest/gtest.h>

#include <cmath>

namespace scanclean {
namespace {

// A range image of the cap of a sphere of radius R about the origin, seen from +z: grid cell
// (r, c) holds the point above (x, y) = ((c - cols / 2) step, (r - rows / 2) step); cells
// outside the cap's rim stay empty. With flip_columns the grid's columns run the other way
// (the other handedness).
PointCloud sphere_cap(int rows, int cols, double step, double R, bool flip_columns = false) {
  PointCloud c;
  c.grid.rows = rows;
  c.grid.cols = cols;
  c.grid.index.assign(static_cast<std::size_t>(rows) * cols, -1);
  for (int r = 0; r < rows; ++r)
    for (int k = 0; k < cols; ++k) {
      const double x = (k - cols / 2) * step, y = (r - rows / 2) * step;
      const double z2 = R * R - x * x - y * y;
      if (z2 < 0.25 * R * R) continue;  // beyond 60 degrees from the view axis
      const int col = flip_columns ? cols - 1 - k : k;
      c.grid.index[static_cast<std::size_t>(r) * cols + col] = static_cast<std::int32_t>(c.size());
      c.positions.emplace_back(x, y, std::sqrt(z2));
    }
  return c;
}

TEST(RangeGridNormalsTest, SphereCapNormalsAreTheOutwardRadii) {
  for (const bool flip : {false, true}) {
    const PointCloud cap = sphere_cap(60, 80, 0.01, 1.0, flip);
    const RangeGridNormals n = range_grid_normals(cap, Eigen::Vector3d::UnitZ());
    ASSERT_EQ(n.normals.size(), cap.size());
    std::size_t checked = 0;
    for (std::size_t i = 0; i < cap.size(); ++i) {
      if (n.normals[i].isZero()) continue;
      const Eigen::Vector3d exact = cap.positions[i].normalized();
      // Central differences on a sphere: the normal is exact up to O(step^2).
      EXPECT_GT(n.normals[i].cast<double>().dot(exact), std::cos(0.2 * M_PI / 180)) << i;
      EXPECT_NEAR(n.normals[i].norm(), 1.0f, 1e-6f);
      ++checked;
    }
    EXPECT_EQ(checked, n.with_normal);
    EXPECT_EQ(n.facing, n.with_normal);
    // Every point but those within the stencil (2 cells) of the grid's border or the rim.
    EXPECT_GT(n.with_normal, cap.size() * 8 / 10) << "flip " << flip;
    EXPECT_LT(n.with_normal, cap.size());
  }
}

TEST(RangeGridNormalsTest, TurnsTowardAViewpoint) {
  // The cap of the unit sphere about the origin: seen from (0, 0, 3) its normals are the outward
  // radii; from the centre, where every point of the cap looks at the viewpoint from the inside,
  // the inward ones.
  const PointCloud cap = sphere_cap(40, 40, 0.01, 1.0);
  const RangeGridNormals outside = range_grid_normals_from_viewpoint(cap, Eigen::Vector3d(0, 0, 3));
  const RangeGridNormals centre = range_grid_normals_from_viewpoint(cap, Eigen::Vector3d::Zero());
  ASSERT_GT(outside.with_normal, cap.size() / 2);
  EXPECT_EQ(outside.facing, outside.with_normal);
  EXPECT_EQ(centre.facing, centre.with_normal);
  for (std::size_t i = 0; i < cap.size(); ++i) {
    if (outside.normals[i].isZero()) continue;
    EXPECT_GT(outside.normals[i].cast<double>().dot(cap.positions[i]), 0.99) << i;
    EXPECT_EQ(centre.normals[i], -outside.normals[i]) << i;
  }
  // From the side: part of the cap faces the viewpoint, part faces away. One sign for the
  // whole grid, that of the majority; `facing` counts the normals that face it.
  const Eigen::Vector3d side(6, 0, 2);
  const RangeGridNormals s = range_grid_normals_from_viewpoint(cap, side);
  std::size_t facing = 0;
  for (std::size_t i = 0; i < cap.size(); ++i) {
    if (s.normals[i].isZero()) continue;
    EXPECT_EQ(s.normals[i], outside.normals[i]) << i;  // most face it outward
    facing += s.normals[i].cast<double>().dot(side - cap.positions[i]) > 0 ? 1 : 0;
  }
  EXPECT_EQ(s.facing, facing);
  EXPECT_LT(s.facing, s.with_normal);
  EXPECT_GT(s.facing, s.with_normal / 2);
}

TEST(RangeGridNormalsTest, TurnsTowardTheGivenSide) {
  const PointCloud cap = sphere_cap(40, 40, 0.01, 1.0);
  const RangeGridNormals up = range_grid_normals(cap, Eigen::Vector3d::UnitZ());
  const RangeGridNormals down = range_grid_normals(cap, -Eigen::Vector3d::UnitZ());
  ASSERT_GT(up.with_normal, 0u);
  EXPECT_EQ(down.with_normal, up.with_normal);
  EXPECT_EQ(down.facing, down.with_normal);
  for (std::size_t i = 0; i < cap.size(); ++i) EXPECT_EQ(down.normals[i], -up.normals[i]);
}

TEST(RangeGridNormalsTest, NoNormalAcrossADepthJumpAtTheBorderOrBesideAHole) {
  // Two planes facing +z, 1 m apart in depth, meeting at column 10 of a 20 x 20 grid with
  // 1 cm cells; one empty cell at (15, 15).
  PointCloud c;
  c.grid.rows = c.grid.cols = 20;
  c.grid.index.assign(400, -1);
  for (int r = 0; r < 20; ++r)
    for (int k = 0; k < 20; ++k) {
      if (r == 15 && k == 15) continue;
      c.grid.index[static_cast<std::size_t>(r) * 20 + k] = static_cast<std::int32_t>(c.size());
      c.positions.emplace_back(0.01 * k, 0.01 * r, k < 10 ? 1.0 : 2.0);
    }
  const RangeGridNormals n = range_grid_normals(c, Eigen::Vector3d::UnitZ());
  for (int r = 0; r < 20; ++r)
    for (int k = 0; k < 20; ++k) {
      const std::int32_t i = c.grid.at(r, k);
      if (i < 0) continue;
      const bool border = r < 2 || r >= 18 || k < 2 || k >= 18;
      const bool jump = k >= 8 && k < 12;  // the stencil reaches across column 9 | 10
      const bool hole = (r == 15 && (k == 13 || k == 17)) || (k == 15 && (r == 13 || r == 17));
      const Eigen::Vector3f& v = n.normals[static_cast<std::size_t>(i)];
      if (border || jump || hole)
        EXPECT_TRUE(v.isZero()) << r << " " << k;
      else
        EXPECT_TRUE(v.isApprox(Eigen::Vector3f::UnitZ())) << r << " " << k;
    }
}

TEST(RangeGridNormalsTest, NoGridNoNormals) {
  PointCloud c;
  c.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  const RangeGridNormals n = range_grid_normals(c, Eigen::Vector3d::UnitZ());
  ASSERT_EQ(n.normals.size(), 3u);
  EXPECT_EQ(n.with_normal, 0u);
  for (const auto& v : n.normals) EXPECT_TRUE(v.isZero());
}

}  // namespace
}  // namespace scanclean

// fuse_static_clouds: per-pixel temporal fusion of organized clouds of one static view, against
// hand-computed means, weights and rejections.

#include <gtest/gtest.h>

#include <optional>
#include <vector>

#include "scanclean/core/errors.h"
#include "scanclean/pipeline/accumulate.h"

namespace scanclean {
namespace {

// A 2x2 organized cloud: pixel (row, col) -> depth z along the ray (x = col, y = row) or no
// point when z <= 0; every point gets normal (0, 0, -1) and the given confidence.
PointCloud grid_cloud(const std::vector<double>& z, float confidence) {
  PointCloud c;
  c.grid.rows = 2;
  c.grid.cols = 2;
  c.grid.index.assign(4, -1);
  for (int cell = 0; cell < 4; ++cell) {
    if (z[cell] <= 0) continue;
    c.grid.index[cell] = static_cast<std::int32_t>(c.positions.size());
    c.positions.emplace_back(0.01 * (cell % 2) * z[cell], 0.01 * (cell / 2) * z[cell], z[cell]);
    c.normals.emplace_back(0.0f, 0.0f, -1.0f);
    c.confidences.push_back(confidence);
  }
  return c;
}

TEST(FuseStaticCloudsTest, AveragesConsistentSamplesAndWeightsByCount) {
  // Pixel 0: 2.00, 2.01, 2.02, 1.99 m -> mean 2.005; pixel 1: seen in 2 of 4 frames;
  // pixel 2: three samples near 1 m and a flying sample at 3 m (rejected); pixel 3: never.
  const std::vector<PointCloud> frames = {
      grid_cloud({2.00, 1.0, 1.000, 0}, 1.0f), grid_cloud({2.01, 1.0, 1.002, 0}, 0.5f),
      grid_cloud({2.02, 0, 3.000, 0}, 1.0f), grid_cloud({1.99, 0, 1.004, 0}, 0.5f)};
  std::size_t rejected = 0;
  const std::optional<PointCloud> f = fuse_static_clouds(frames, {}, &rejected);
  ASSERT_TRUE(f.has_value());
  EXPECT_EQ(rejected, 1u);
  ASSERT_EQ(f->size(), 3u);
  EXPECT_EQ(f->grid.rows, 2);
  EXPECT_EQ(f->grid.index[3], -1);
  const auto at = [&](int cell) { return static_cast<std::size_t>(f->grid.index[cell]); };
  EXPECT_NEAR(f->positions[at(0)].z(), 2.005, 1e-12);
  EXPECT_NEAR(f->positions[at(2)].z(), 1.002, 1e-12);  // 3 m dropped: 1.000, 1.002, 1.004
  // Confidence = sum of the kept samples' confidences / frames.
  EXPECT_NEAR(f->confidences[at(0)], (1 + 0.5 + 1 + 0.5) / 4.0, 1e-6);
  EXPECT_NEAR(f->confidences[at(1)], (1 + 0.5) / 4.0, 1e-6);
  EXPECT_NEAR(f->confidences[at(2)], (1 + 0.5 + 0.5) / 4.0, 1e-6);
  EXPECT_NEAR((f->normals[at(0)] - Eigen::Vector3f(0, 0, -1)).norm(), 0.0f, 1e-6f);
}

TEST(FuseStaticCloudsTest, RefusesCloudsOfDifferentGridsAndBadOptions) {
  PointCloud a = grid_cloud({1, 1, 1, 1}, 1.0f);
  PointCloud b = a;
  b.grid.cols = 4;
  b.grid.rows = 1;
  EXPECT_FALSE(fuse_static_clouds({a, b}).has_value());
  PointCloud unorganized = a;
  unorganized.grid = {};
  EXPECT_FALSE(fuse_static_clouds({unorganized, unorganized}).has_value());
  FuseOptions bad;
  bad.max_depth_deviation_factor = 0;
  EXPECT_THROW(fuse_static_clouds({a, a}, bad), OptionError);
}

}  // namespace
}  // namespace scanclean

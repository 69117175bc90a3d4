#include "scanclean/core/point_cloud.h"

#include <gtest/gtest.h>

#include <stdexcept>

namespace scanclean {
namespace {

PointCloud three_points() {
  PointCloud c;
  c.positions = {{0, 0, 0}, {1, 2, 3}, {-1, 5, 2}};
  c.confidences = {0.5f, 1.0f, 0.25f};
  c.set_attribute("id", AttributeType::kUInt32, {10, 11, 12});
  return c;
}

TEST(PointCloudTest, SelectKeepsEveryArrayInOrder) {
  PointCloud c = three_points();
  PointCloud s = select(c, {2, 0});
  ASSERT_EQ(s.size(), 2u);
  EXPECT_EQ(s.positions[0], Eigen::Vector3d(-1, 5, 2));
  EXPECT_FLOAT_EQ(s.confidences[1], 0.5f);
  ASSERT_NE(s.find_attribute("id"), nullptr);
  EXPECT_EQ(s.find_attribute("id")->values, (std::vector<double>{12, 10}));
  EXPECT_FALSE(s.has_normals());
}

TEST(PointCloudTest, SelectRemapsTheGrid) {
  PointCloud c = three_points();
  c.grid.rows = 2;
  c.grid.cols = 2;
  c.grid.index = {0, -1, 1, 2};
  PointCloud s = select(c, {2, 1});
  EXPECT_EQ(s.grid.index, (std::vector<std::int32_t>{-1, -1, 1, 0}));
  EXPECT_NO_THROW(s.check_consistent());
}

TEST(PointCloudTest, AppendFillsMissingArraysWithDefaults) {
  PointCloud a = three_points();
  PointCloud b;
  b.positions = {{7, 7, 7}};
  b.normals = {{0, 0, 1}};
  append(a, b);
  ASSERT_EQ(a.size(), 4u);
  ASSERT_EQ(a.normals.size(), 4u);
  EXPECT_EQ(a.normals[0], Eigen::Vector3f::Zero());
  EXPECT_EQ(a.normals[3], Eigen::Vector3f(0, 0, 1));
  EXPECT_FLOAT_EQ(a.confidences[3], 1.0f);
  EXPECT_EQ(a.find_attribute("id")->values.size(), 4u);
  EXPECT_NO_THROW(a.check_consistent());
}

TEST(PointCloudTest, InconsistentSizesAreDetected) {
  PointCloud c = three_points();
  c.normals = {{0, 0, 1}};
  EXPECT_THROW(c.check_consistent(), std::logic_error);
  EXPECT_THROW(c.set_attribute("bad", AttributeType::kFloat32, {1.0}), std::logic_error);
}

TEST(PointCloudTest, TransformRotatesNormalsAndMovesPoints) {
  PointCloud c;
  c.positions = {{1, 0, 0}};
  c.normals = {{1, 0, 0}};
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(0, 0, 5);
  transform(c, T);
  EXPECT_NEAR((c.positions[0] - Eigen::Vector3d(0, 1, 5)).norm(), 0.0, 1e-12);
  EXPECT_NEAR((c.normals[0] - Eigen::Vector3f(0, 1, 0)).norm(), 0.0, 1e-6);
  auto box = bounding_box(c);
  EXPECT_NEAR(box.min().z(), 5.0, 1e-12);
}

}  // namespace
}  // namespace scanclean

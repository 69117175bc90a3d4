#include "scanclean/io/xyz.h"

#include <gtest/gtest.h>

#include "io_test_util.h"
#include "scanclean/io/point_cloud_io.h"
#include "support/data_paths.h"

namespace scanclean {
namespace {

class XyzTest : public ::testing::Test {
 protected:
  void SetUp() override { dir_ = test::make_temp_dir("xyz"); }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::filesystem::path dir_;
};

TEST_F(XyzTest, ReadsCommentsBlankLinesNormalsAndDropsNonFinite) {
  const auto p = test::write_bytes(dir_ / "a.xyz",
                                   "# header comment\n\n1 2 3 0 0 1\n  4\t5 6 1 0 0 # tail\r\n"
                                   "nan 1 1 0 1 0\n+7 -8e-3 9 0 1 0\n");
  ReadReport r;
  const PointCloud c = read_xyz(p, &r);
  ASSERT_EQ(c.size(), 3u);
  EXPECT_EQ(c.positions[2], Eigen::Vector3d(7, -8e-3, 9));
  ASSERT_TRUE(c.has_normals());
  EXPECT_EQ(c.normals[1], Eigen::Vector3f(1, 0, 0));
  EXPECT_EQ(r.dropped_invalid, 1u);
  EXPECT_EQ(r.declared_points, 4u);
}

TEST_F(XyzTest, RoundTripsExactlyThroughTxtAndXyz) {
  PointCloud c = test::full_cloud(100, 5);   // seed 5
  c.positions[3] = {0.1, 1.0 / 3.0, -2e-9};  // not float-representable: text keeps every digit
  for (const char* name : {"b.xyz", "b.txt"}) {
    write_point_cloud(dir_ / name, c);
    const PointCloud back = read_point_cloud(dir_ / name);
    test::expect_same_cloud(c, back, false);
    EXPECT_EQ(back.normals, c.normals);
  }
}

TEST_F(XyzTest, MalformedLinesNameTheLine) {
  const std::string m1 =
      test::input_error_of([&] { read_xyz(test::write_bytes(dir_ / "c.xyz", "1 2 3\n4 5\n")); });
  EXPECT_NE(m1.find("c.xyz: line 2"), std::string::npos) << m1;
  EXPECT_NE(m1.find("expected 3 numbers"), std::string::npos) << m1;
  const std::string m2 = test::input_error_of(
      [&] { read_xyz(test::write_bytes(dir_ / "d.xyz", "# c\n1 2 3 4 5\n")); });
  EXPECT_NE(m2.find("line 2"), std::string::npos) << m2;
  const std::string m3 = test::input_error_of(
      [&] { read_xyz(test::write_bytes(dir_ / "e.xyz", "1 2 3\n1 two 3\n")); });
  EXPECT_NE(m3.find("line 2"), std::string::npos) << m3;
  EXPECT_NE(m3.find("'two'"), std::string::npos) << m3;
}

TEST_F(XyzTest, DispatchRejectsUnknownExtensions) {
  const std::string m = test::input_error_of(
      [&] { read_point_cloud(test::write_bytes(dir_ / "f.obj", "v 1 2 3\n")); });
  EXPECT_NE(m.find("'.obj'"), std::string::npos) << m;
  EXPECT_THROW(write_point_cloud(dir_ / "g.obj", PointCloud{}), OptionError);
  WriteOptions bad;
  bad.pcd_encoding = "gzip";
  EXPECT_THROW(write_point_cloud(dir_ / "g.pcd", PointCloud{}, bad), OptionError);
  EXPECT_THROW(read_point_cloud(dir_ / "missing.ply"), IoError);
}

}  // namespace
}  // namespace scanclean

#include "scanclean/io/stanford_conf.h"

#include <gtest/gtest.h>

#include <algorithm>

#include "io_test_util.h"
#include "scanclean/eval/mesh_distance.h"
#include "scanclean/io/point_cloud_io.h"
#include "scanclean/io/triangle_mesh_io.h"
#include "support/data_paths.h"

namespace scanclean {
namespace {

class StanfordConfTest : public ::testing::Test {
 protected:
  void SetUp() override { dir_ = test::make_temp_dir("conf"); }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::filesystem::path dir_;
};

TEST_F(StanfordConfTest, ParsesBmeshLinesRelativeToTheConfFolder) {
  const auto conf = test::write_bytes(dir_ / "s.conf",
                                      "camera 0 0 -1 0 0 0 1\nmesh recon 0 0 0 0 0 0 1\n"
                                      "bmesh a.xyz 1 2 3 0 0 0 1\nbmesh sub/b.xyz 0 0 0 0 "
                                      "0.7071067811865476 0 0.7071067811865476\n");
  ReadReport r;
  const ScanSession s = read_conf(conf, &r);
  ASSERT_EQ(s.files.size(), 2u);
  EXPECT_EQ(s.files[1], dir_ / "sub/b.xyz");
  EXPECT_EQ(s.lines[1], 4u);
  EXPECT_TRUE(s.poses[0].isApprox(Eigen::Isometry3d(Eigen::Translation3d(1, 2, 3))));
  // Conjugate convention: q = 90 degrees about +y maps x to +z (R(q) would map it to -z).
  EXPECT_TRUE((s.poses[1] * Eigen::Vector3d::UnitX()).isApprox(Eigen::Vector3d::UnitZ(), 1e-12));
  ASSERT_EQ(r.warnings.size(), 1u);  // the mesh line
  EXPECT_NE(r.warnings[0].find("line 2"), std::string::npos);
}

TEST_F(StanfordConfTest, MergesScansAndHandlesMissingFilesByPolicy) {
  test::write_bytes(dir_ / "a.xyz", "0 0 0\n1 0 0\n");
  const auto conf = test::write_bytes(dir_ / "m.conf",
                                      "bmesh a.xyz 0 0 1 0 0 0 1\nbmesh gone.xyz 0 0 0 0 0 0 1\n");
  const std::string msg = test::input_error_of([&] { read_and_merge_conf(conf); });
  EXPECT_NE(msg.find("m.conf: line 2"), std::string::npos) << msg;
  EXPECT_NE(msg.find("gone.xyz"), std::string::npos) << msg;
  ReadReport r;
  const PointCloud c = read_and_merge_conf(conf, &r, ConfOptions{true});
  ASSERT_EQ(c.size(), 2u);
  EXPECT_EQ(c.positions[1], Eigen::Vector3d(1, 0, 1));
  // An .xyz scan has no range grid: no normals from the scanner, and a warning that says so.
  EXPECT_FALSE(c.has_normals());
  ASSERT_EQ(r.warnings.size(), 2u);
  EXPECT_NE(r.warnings[0].find("a.xyz: no range grid"), std::string::npos) << r.warnings[0];
  EXPECT_NE(r.warnings[1].find("gone.xyz"), std::string::npos);
}

TEST_F(StanfordConfTest, MalformedConfLinesNameTheLine) {
  const auto bad = test::write_bytes(dir_ / "b.conf", "bmesh a.ply 0 0 0 0 0 1\n");
  EXPECT_NE(test::input_error_of([&] { read_conf(bad); }).find("b.conf: line 1"),
            std::string::npos);
  const auto zero = test::write_bytes(dir_ / "z.conf", "\nbmesh a.ply 0 0 0 0 0 0 0\n");
  EXPECT_NE(test::input_error_of([&] { read_conf(zero); }).find("line 2"), std::string::npos);
  const auto none = test::write_bytes(dir_ / "n.conf", "camera 0 0 0 0 0 0 1\n");
  EXPECT_NE(test::input_error_of([&] { read_conf(none); }).find("no 'bmesh"), std::string::npos);
}

// The convention check on real data: the merged bun.conf scans must lie on bun_zipper.ply.
TEST(StanfordBunnyConfTest, MergedScansLieOnTheReconstruction) {
  SCANCLEAN_REQUIRE_SHARED("stanford_bunny/data/bun.conf");
  const auto root = test::shared_data_dir() / "stanford_bunny";
  ReadReport r;
  const PointCloud merged =
      read_and_merge_conf(root / "data/bun.conf", &r, ConfOptions{/*skip_missing=*/true});
  // 8 of the 10 listed scans exist (bun315.ply and top3.ply are not shipped).
  EXPECT_EQ(merged.size(), 40256u + 40097u + 30379u + 40251u + 31701u + 38298u + 37738u + 32193u);
  EXPECT_EQ(std::count_if(
                r.warnings.begin(), r.warnings.end(),
                [](const std::string& w) { return w.find("does not exist") != std::string::npos; }),
            2);
  EXPECT_THROW(read_and_merge_conf(root / "data/bun.conf"), InputError);  // default: strict

  const MeshDistance md(read_triangle_mesh(root / "reconstruction/bun_zipper.ply"));
  std::vector<double> d;
  for (std::size_t i = 0; i < merged.size(); i += 7) d.push_back(md.distance(merged.positions[i]));
  std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
  const double median = d[d.size() / 2];
  RecordProperty("median_distance_mm", std::to_string(median * 1e3));
  std::printf("merged bunny scans: %zu points, median distance to bun_zipper.ply %.4f mm\n",
              merged.size(), median * 1e3);
  EXPECT_LT(median, 0.2e-3);  // well under a millimetre (measured ~0.06 mm)

  // The normals from the scans' range grids face the way bun_zipper.ply's triangles do (out of
  // the bunny) at the closest point of the mesh (all of the sampled ones did).
  ASSERT_TRUE(merged.has_normals());
  const TriangleMesh mesh = read_triangle_mesh(root / "reconstruction/bun_zipper.ply");
  std::size_t with = 0, agree = 0, sampled = 0;
  for (std::size_t i = 0; i < merged.size(); i += 7, ++sampled) {
    if (merged.normals[i].isZero()) continue;
    ++with;
    const auto& t = mesh.triangles[md.query(merged.positions[i]).triangle];
    const Eigen::Vector3d& a = mesh.vertices[static_cast<std::size_t>(t[0])];
    const Eigen::Vector3d face = (mesh.vertices[static_cast<std::size_t>(t[1])] - a)
                                     .cross(mesh.vertices[static_cast<std::size_t>(t[2])] - a);
    agree += merged.normals[i].cast<double>().dot(face) > 0 ? 1 : 0;
  }
  std::printf(
      "merged bunny scans: %zu of %zu sampled points with a scan normal, %zu (%.2f %%) "
      "facing as bun_zipper.ply\n",
      with, sampled, agree, 100.0 * static_cast<double>(agree) / static_cast<double>(with));
  EXPECT_GT(with, sampled * 8 / 10);  // 85 %: the others at holes, grid borders and depth jumps
  EXPECT_GT(agree, with * 97 / 100);
  for (const auto& w : r.warnings)
    EXPECT_EQ(w.find("normals of its range grid"), std::string::npos);

  // The other conventions put scans centimetres away: the check above can fail.
  const ScanSession s = read_conf(root / "data/bun.conf");
  const PointCloud chin = read_point_cloud(root / "data/chin.ply");
  const auto it = std::find(s.files.begin(), s.files.end(), root / "data/chin.ply");
  ASSERT_NE(it, s.files.end());
  const Eigen::Isometry3d pose = s.poses[static_cast<std::size_t>(it - s.files.begin())];
  Eigen::Isometry3d plain_q = pose;
  plain_q.linear() = pose.linear().transpose();  // R(q) instead of R(conj q)
  std::vector<double> good, bad;
  for (std::size_t i = 0; i < chin.size(); i += 50) {
    good.push_back(md.distance(pose * chin.positions[i]));
    bad.push_back(md.distance(plain_q * chin.positions[i]));
  }
  std::nth_element(good.begin(), good.begin() + good.size() / 2, good.end());
  std::nth_element(bad.begin(), bad.begin() + bad.size() / 2, bad.end());
  EXPECT_LT(good[good.size() / 2], 0.2e-3);
  EXPECT_GT(bad[bad.size() / 2], 10e-3);
}

}  // namespace
}  // namespace scanclean

// Provenance in written PLY and PCD headers (WriteOptions::provenance): the version comment is
// always there, the provenance text only when given, on one line whatever it contains, and the
// files still read back unchanged without warnings.

#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <string>

#include "io_test_util.h"
#include "scanclean/io/point_cloud_io.h"
#include "support/data_paths.h"

namespace scanclean {
namespace {

//! The header of a PLY (up to end_header) or PCD (up to the DATA line) file.
std::string header_of(const std::filesystem::path& file) {
  const std::string bytes = test::read_bytes(file);
  const auto ply_end = bytes.find("end_header\n");
  if (ply_end != std::string::npos) return bytes.substr(0, ply_end);
  return bytes.substr(0, bytes.find("\nDATA "));
}

class ProvenanceTest : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override { dir_ = test::make_temp_dir("provenance"); }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::filesystem::path dir_;
};

TEST_P(ProvenanceTest, VersionAlwaysProvenanceWhenGivenOnOneLine) {
  const PointCloud cloud = test::full_cloud(50, 11);
  const std::string ext = GetParam();
  const bool ply = ext.rfind(".ply", 0) == 0;
  const std::string mark = ply ? "comment " : "# ";
  WriteOptions w;
  if (ext == ".ply-ascii") w.ply_encoding = PlyEncoding::kAscii;
  if (ext == ".pcd-ascii") w.pcd_encoding = "ascii";
  const std::string suffix = ply ? ".ply" : ".pcd";

  const auto plain = dir_ / ("plain" + suffix);
  write_point_cloud(plain, cloud, w);
  const std::string h0 = header_of(plain);
  // "written by scanclean <major>.<minor>.<patch>" (no std::regex: GCC 12 warns inside it).
  const auto at = h0.find("written by scanclean ");
  ASSERT_NE(at, std::string::npos) << h0;
  const std::string version = h0.substr(at + 21, h0.find_first_of(" ;\n", at + 21) - (at + 21));
  EXPECT_TRUE(!version.empty() && std::isdigit(static_cast<unsigned char>(version[0])) &&
              std::count(version.begin(), version.end(), '.') == 2)
      << h0;

  // A newline and a fake header keyword inside the text must not break out of the comment.
  w.provenance = "scanclean filter in.ply -o out.ply --h 0.002\nend_header\r\tDATA ascii";
  const auto with = dir_ / ("with" + suffix);
  write_point_cloud(with, cloud, w);
  const std::string h1 = header_of(with);
  EXPECT_NE(h1.find("\n" + mark +
                    "scanclean filter in.ply -o out.ply --h 0.002 end_header  DATA ascii\n"),
            std::string::npos)
      << h1;
  EXPECT_EQ(h1.size(), h0.size() + mark.size() + w.provenance.size() + 1);

  ReadReport report;
  const PointCloud back = read_point_cloud(with, &report);
  EXPECT_TRUE(report.warnings.empty()) << report.warnings.front();
  const PointCloud back_plain = read_point_cloud(plain);
  ASSERT_EQ(back.size(), cloud.size());
  EXPECT_EQ(back.positions, back_plain.positions);
  EXPECT_EQ(back.normals, back_plain.normals);
  EXPECT_EQ(back.colors, back_plain.colors);
}

INSTANTIATE_TEST_SUITE_P(Writers, ProvenanceTest,
                         ::testing::Values(".ply", ".ply-ascii", ".pcd", ".pcd-ascii"));

}  // namespace
}  // namespace scanclean

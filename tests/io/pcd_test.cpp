#include "scanclean/io/pcd.h"

#include <gtest/gtest.h>
#include <lzf.h>

#include <cmath>
#include <limits>

#include "io_test_util.h"
#include "scanclean/core/errors.h"
#include "support/data_paths.h"

namespace scanclean {
namespace {

using test::bytes_le;
using test::input_error_of;
using test::write_bytes;

class PcdTest : public ::testing::Test {
 protected:
  void SetUp() override { dir_ = test::make_temp_dir("pcd"); }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::filesystem::path file(const std::string& name, const std::string& content) {
    return write_bytes(dir_ / name, content);
  }
  std::filesystem::path dir_;
};

std::string header(const std::string& fields, const std::string& size, const std::string& type,
                   const std::string& count, int width, int height, const std::string& data,
                   const std::string& version = "0.7") {
  return "# .PCD v" + version + " - Point Cloud Data file format\nVERSION " + version +
         "\nFIELDS " + fields + "\nSIZE " + size + "\nTYPE " + type + "\nCOUNT " + count +
         "\nWIDTH " + std::to_string(width) + "\nHEIGHT " + std::to_string(height) +
         "\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " + std::to_string(width * height) + "\nDATA " + data +
         "\n";
}

TEST_F(PcdTest, FullCloudRoundTripsInEveryEncoding) {
  const PointCloud c = test::full_cloud(300, 11);  // seed 11
  for (const std::string enc : {"ascii", "binary", "binary_compressed"}) {
    write_pcd(dir_ / "full.pcd", c, enc);
    ReadReport r;
    const PointCloud back = read_pcd(dir_ / "full.pcd", &r);
    EXPECT_EQ(r.encoding, enc);
    test::expect_same_cloud(c, back);
    EXPECT_TRUE(r.warnings.empty()) << enc << ": " << r.warnings.front();
  }
}

TEST_F(PcdTest, OrganizedCloudKeepsWidthHeightAndEmptyCellsThroughARoundTrip) {
  PointCloud c;
  c.grid.rows = 2;
  c.grid.cols = 3;
  c.grid.index = {0, -1, 1, -1, 2, 3};
  for (int i = 0; i < 4; ++i) c.positions.emplace_back(0.5 * i, 1.0, 2.0 - i);
  for (const std::string enc : {"ascii", "binary", "binary_compressed"}) {
    write_pcd(dir_ / "org.pcd", c, enc);
    const std::string text = test::read_bytes(dir_ / "org.pcd");
    EXPECT_NE(text.find("WIDTH 3\nHEIGHT 2\n"), std::string::npos) << enc;
    ReadReport r;
    const PointCloud back = read_pcd(dir_ / "org.pcd", &r);
    test::expect_same_cloud(c, back);
    EXPECT_EQ(r.dropped_invalid, 2u) << enc;  // the two empty cells were written as NaN
    EXPECT_EQ(r.declared_points, 6u);
  }
}

TEST_F(PcdTest, UnorganizedNaNPointsAreDroppedAndCounted) {
  const auto p = file("nan.pcd", header("x y z", "4 4 4", "F F F", "1 1 1", 4, 1, "ascii") +
                                     "1 2 3\nnan nan nan\n4 5 6\n7 nan 9\n");
  ReadReport r;
  const PointCloud c = read_pcd(p, &r);
  ASSERT_EQ(c.size(), 2u);
  EXPECT_EQ(c.positions[1], Eigen::Vector3d(4, 5, 6));
  EXPECT_EQ(r.dropped_invalid, 2u);
  EXPECT_TRUE(c.grid.empty());
  ASSERT_EQ(r.warnings.size(), 1u);
  EXPECT_NE(r.warnings[0].find("2 of 4"), std::string::npos);
}

TEST_F(PcdTest, PackedRgbFloatAndRgbaUintBecomeColours) {
  float packed;
  const std::uint32_t bits = (10u << 16) | (20u << 8) | 30u;
  std::memcpy(&packed, &bits, 4);
  const std::string rgb_binary =
      header("x y z rgb", "4 4 4 4", "F F F F", "1 1 1 1", 1, 1, "binary") + bytes_le(1.f) +
      bytes_le(2.f) + bytes_le(3.f) + bytes_le(packed);
  PointCloud c = read_pcd(file("rgb.pcd", rgb_binary));
  ASSERT_TRUE(c.has_colors());
  EXPECT_EQ(c.colors[0], (std::array<std::uint8_t, 4>{10, 20, 30, 255}));
  const std::uint32_t rgba = (40u << 24) | (1u << 16) | (2u << 8) | 3u;
  c = read_pcd(
      file("rgba.pcd", header("x y z rgba", "4 4 4 4", "F F F U", "1 1 1 1", 1, 1, "ascii") +
                           "1 2 3 " + std::to_string(rgba) + "\n"));
  EXPECT_EQ(c.colors[0], (std::array<std::uint8_t, 4>{1, 2, 3, 40}));
}

TEST_F(PcdTest, CountAboveOneFieldsAreSkippedAndOtherFieldsKept) {
  // x y z, a 3-bin histogram, curvature (attribute), intensity; older .5 header.
  std::string body;
  for (int i = 0; i < 2; ++i) {
    body += bytes_le(float(i)) + bytes_le(2.f) + bytes_le(3.f);
    body += bytes_le(9.f) + bytes_le(9.f) + bytes_le(9.f);
    body += bytes_le(0.25f * i) + bytes_le(std::uint16_t(100 + i));
  }
  ReadReport r;
  const PointCloud c =
      read_pcd(file("hist.pcd", header("x y z hist curvature intensity", "4 4 4 4 4 2",
                                       "F F F F F U", "1 1 1 3 1 1", 2, 1, "binary", ".5") +
                                    body),
               &r);
  ASSERT_EQ(c.size(), 2u);
  EXPECT_EQ(c.positions[1], Eigen::Vector3d(1, 2, 3));
  const Attribute* curv = c.find_attribute("curvature");
  ASSERT_NE(curv, nullptr);
  EXPECT_EQ(curv->values, (std::vector<double>{0.0, 0.25}));
  EXPECT_EQ(c.intensities, (std::vector<float>{100.f, 101.f}));
  EXPECT_EQ(c.find_attribute("hist"), nullptr);
  ASSERT_EQ(r.warnings.size(), 1u);
  EXPECT_NE(r.warnings[0].find("'hist' with COUNT 3"), std::string::npos) << r.warnings[0];
}

std::string compressed_body(const std::string& raw, std::uint32_t claimed_usize) {
  std::string out(raw.size() + raw.size() / 16 + 64, '\0');
  const unsigned c = lzf_compress(raw.data(), static_cast<unsigned>(raw.size()), out.data(),
                                  static_cast<unsigned>(out.size()));
  out.resize(c);
  return bytes_le(std::uint32_t(c)) + bytes_le(claimed_usize) + out;
}

TEST_F(PcdTest, MalformedFilesGiveInputErrorsWithPlace) {
  std::string raw;  // 4 points x y z, struct of arrays
  for (int f = 0; f < 3; ++f)
    for (int i = 0; i < 4; ++i) raw += bytes_le(float(i + f));
  const std::string h4c = header("x y z", "4 4 4", "F F F", "1 1 1", 4, 1, "binary_compressed");
  std::string corrupt = compressed_body(raw, 48);
  corrupt[8] = static_cast<char>(0x20);  // first control byte: a back-reference before the start
  std::string short_payload = compressed_body(raw, 48);
  {
    const std::uint32_t csize = static_cast<std::uint32_t>(short_payload.size() - 8 - 5);
    std::memcpy(short_payload.data(), &csize, 4);  // the payload ends 5 bytes early
  }
  struct Case {
    const char* name;
    std::string content;
    std::vector<std::string> expected;
  };
  const std::vector<Case> cases = {
      {"empty", "", {"empty file"}},
      {"no_data_line", "VERSION 0.7\nFIELDS x y z\n", {"DATA"}},
      {"size_mismatch",
       header("x y z", "4 4", "F F F", "1 1 1", 1, 1, "ascii") + "1 2 3\n",
       {"line 4", "SIZE has 2 entries", "FIELDS"}},
      {"type_mismatch",
       header("x y z", "4 4 4", "F F", "1 1 1", 1, 1, "ascii"),
       {"line 5", "TYPE has 2"}},
      {"count_mismatch",
       header("x y z", "4 4 4", "F F F", "1 1", 1, 1, "ascii"),
       {"line 6", "COUNT has 2"}},
      {"bad_type", header("x y z", "4 4 4", "F F Q", "1 1 1", 1, 1, "ascii"), {"line 5", "'Q'"}},
      {"bad_size", header("x y z", "4 4 3", "F F F", "1 1 1", 1, 1, "ascii"), {"line 4", "SIZE 3"}},
      {"float_size_2",
       header("x y z", "4 4 2", "F F F", "1 1 1", 1, 1, "ascii"),
       {"TYPE F with SIZE 2"}},
      {"unknown_encoding",
       header("x y z", "4 4 4", "F F F", "1 1 1", 1, 1, "zip"),
       {"line 11", "'zip'"}},
      {"points_mismatch",
       "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 3\nHEIGHT 1\nPOINTS 5\n"
       "DATA ascii\n",
       {"POINTS 5", "WIDTH x HEIGHT"}},
      {"missing_z", header("x y", "4 4", "F F", "1 1", 1, 1, "ascii") + "1 2\n", {"no z"}},
      {"ascii_truncated",
       header("x y z", "4 4 4", "F F F", "1 1 1", 3, 1, "ascii") + "1.0000 2.0000 3.0000\n",
       {"line 13", "after 1 of 3 points"}},
      {"ascii_wrong_values",
       header("x y z", "4 4 4", "F F F", "1 1 1", 2, 1, "ascii") + "1.0 2.0 3.0\n4.0 5.0\n",
       {"line 13", "expected 3 values, found 2"}},
      {"ascii_not_number",
       header("x y z", "4 4 4", "F F F", "1 1 1", 1, 1, "ascii") + "1 x 3\n",
       {"line 12", "'x'"}},
      {"binary_truncated",
       header("x y z", "4 4 4", "F F F", "1 1 1", 2, 1, "binary") + std::string(20, '\0'),
       {"byte", "24 bytes expected, 20 present"}},
      {"lying_points_binary",
       header("x y z", "4 4 4", "F F F", "1 1 1", 2000000000, 1, "binary") + std::string(12, '\0'),
       {"2000000000 points"}},
      {"lying_points_ascii",
       header("x y z", "4 4 4", "F F F", "1 1 1", 2000000000, 1, "ascii") + "1 2 3\n",
       {"POINTS 2000000000", "cannot fit"}},
      {"compressed_no_sizes", h4c + "abc", {"two uint32 sizes"}},
      {"compressed_size_too_big",
       h4c + bytes_le(std::uint32_t(1000)) + bytes_le(std::uint32_t(48)),
       {"compressed size 1000 exceeds"}},
      {"uncompressed_size_mismatch",
       h4c + compressed_body(raw, 40),
       {"uncompressed size 40", "4 x 12 = 48"}},
      {"lzf_corrupt", h4c + corrupt, {"byte", "LZF payload is corrupt"}},
      {"lzf_short", h4c + short_payload, {"LZF payload is corrupt", "expected 48"}},
      {"lying_points_compressed",
       header("x y z", "4 4 4", "F F F", "1 1 1", 100000000, 1, "binary_compressed") +
           compressed_body(raw, 1200000000u),
       {"cannot come from"}},
      {"huge_count",
       header("x y z h", "4 4 4 4", "F F F F", "1 1 1 99999999999", 1, 1, "ascii"),
       {"line 6", "COUNT 99999999999"}},
  };
  for (const auto& c : cases) {
    const std::string msg =
        input_error_of([&] { read_pcd(file(std::string(c.name) + ".pcd", c.content)); });
    EXPECT_NE(msg.find(std::string(c.name) + ".pcd"), std::string::npos) << c.name << ": " << msg;
    for (const auto& e : c.expected)
      EXPECT_NE(msg.find(e), std::string::npos) << c.name << ": '" << e << "' not in: " << msg;
  }
}

TEST_F(PcdTest, WriterRejectsUnknownEncodingAndLeavesNoFile) {
  const PointCloud c = test::full_cloud(5, 1);  // seed 1
  EXPECT_THROW(write_pcd(dir_ / "x.pcd", c, "lz4"), OptionError);
  EXPECT_FALSE(std::filesystem::exists(dir_ / "x.pcd"));
  std::filesystem::create_directory(dir_ / "y.pcd");
  EXPECT_THROW(write_pcd(dir_ / "y.pcd", c), IoError);
  std::size_t entries = 0;
  for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(dir_)) ++entries;
  EXPECT_EQ(entries, 1u);
}

TEST_F(PcdTest, EmptyCloudRoundTrips) {
  for (const std::string enc : {"ascii", "binary", "binary_compressed"}) {
    write_pcd(dir_ / "e.pcd", PointCloud{}, enc);
    EXPECT_EQ(read_pcd(dir_ / "e.pcd").size(), 0u) << enc;
  }
}

}  // namespace
}  // namespace scanclean

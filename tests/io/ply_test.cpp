#include "scanclean/io/ply.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "io_test_util.h"
#include "scanclean/core/errors.h"
#include "scanclean/io/triangle_mesh_io.h"
#include "support/data_paths.h"

namespace scanclean {
namespace {

using test::bytes_be;
using test::bytes_le;
using test::input_error_of;
using test::write_bytes;

class PlyTest : public ::testing::Test {
 protected:
  void SetUp() override { dir_ = test::make_temp_dir("ply"); }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::filesystem::path file(const std::string& name, const std::string& content) {
    return write_bytes(dir_ / name, content);
  }
  std::filesystem::path dir_;
};

TEST_F(PlyTest, FullCloudRoundTripsInBothEncodings) {
  const PointCloud c = test::full_cloud(300, 7);  // seed 7
  for (auto enc : {PlyEncoding::kBinaryLittleEndian, PlyEncoding::kAscii}) {
    const auto p = dir_ / "full.ply";
    write_ply(p, c, enc);
    ReadReport r;
    const PointCloud back = read_ply(p, &r);
    EXPECT_EQ(r.encoding, enc == PlyEncoding::kAscii ? "ascii" : "binary_little_endian");
    test::expect_same_cloud(c, back);
    EXPECT_TRUE(r.warnings.empty());
  }
}

TEST_F(PlyTest, OrganizedGridRoundTrips) {
  PointCloud c;
  c.grid.rows = 3;
  c.grid.cols = 4;
  c.grid.index = {0, -1, 1, 2, -1, -1, 3, 4, 5, -1, 6, -1};
  for (int i = 0; i < 7; ++i) c.positions.emplace_back(i * 0.25, -i * 0.5, 1.0 + i);
  for (auto enc : {PlyEncoding::kBinaryLittleEndian, PlyEncoding::kAscii}) {
    write_ply(dir_ / "grid.ply", c, enc);
    const PointCloud back = read_ply(dir_ / "grid.ply");
    test::expect_same_cloud(c, back);
  }
}

TEST_F(PlyTest, PositionsUseDoubleOnlyWhenFloatWouldLosePrecision) {
  PointCloud far_away;  // 1 mm object 1000 km from the origin: float would move it by ~6 cm
  for (int i = 0; i < 10; ++i)
    far_away.positions.emplace_back(1e6 + i * 1e-4, 2e6, -3e6 + i * 1e-4);
  write_ply(dir_ / "far.ply", far_away, PlyEncoding::kAscii);
  EXPECT_NE(test::read_bytes(dir_ / "far.ply").find("property double x"), std::string::npos);
  test::expect_same_cloud(far_away, read_ply(dir_ / "far.ply"), false);

  PointCloud plain;
  for (int i = 0; i < 10; ++i) plain.positions.emplace_back(0.125 * i, 0.5, -0.25);
  write_ply(dir_ / "plain.ply", plain);
  EXPECT_NE(test::read_bytes(dir_ / "plain.ply").find("property float x"), std::string::npos);
  test::expect_same_cloud(plain, read_ply(dir_ / "plain.ply"), false);
}

TEST_F(PlyTest, ReadsEveryTypeNameInAnyPropertyOrder) {
  const auto p = file("types.ply",
                      "ply\nformat ascii 1.0\ncomment all the types\nobj_info made by hand\n"
                      "element vertex 2\nproperty uchar red\nproperty int8 a\nproperty double z\n"
                      "property short b\nproperty uint16 c\nproperty float32 y\nproperty int32 d\n"
                      "property uint e\nproperty float64 x\nproperty char f\nproperty ushort g\n"
                      "property int h\nproperty uint32 i\nproperty float j\nproperty uint8 green\n"
                      "property int16 k\nproperty uchar blue\nend_header\n"
                      "10 -128 3.5 -32768 65535 2.25 -7 4294967295 1.5 127 0 2147483647 0 0.5 20 "
                      "32767 30\n"
                      "11 127 -3.5 32767 0 -2.25 7 0 -1.5 -128 65535 -2147483648 4294967295 -0.5 "
                      "21 -32768 31\n");
  ReadReport r;
  const PointCloud c = read_ply(p, &r);
  ASSERT_EQ(c.size(), 2u);
  EXPECT_EQ(c.positions[0], Eigen::Vector3d(1.5, 2.25, 3.5));
  EXPECT_EQ(c.positions[1], Eigen::Vector3d(-1.5, -2.25, -3.5));
  ASSERT_TRUE(c.has_colors());
  EXPECT_EQ(c.colors[0], (std::array<std::uint8_t, 4>{10, 20, 30, 255}));
  EXPECT_EQ(c.colors[1], (std::array<std::uint8_t, 4>{11, 21, 31, 255}));
  struct Expect {
    const char* name;
    AttributeType type;
    double v0, v1;
  };
  const Expect expected[] = {{"a", AttributeType::kInt32, -128, 127},
                             {"b", AttributeType::kInt32, -32768, 32767},
                             {"c", AttributeType::kUInt32, 65535, 0},
                             {"d", AttributeType::kInt32, -7, 7},
                             {"e", AttributeType::kUInt32, 4294967295.0, 0},
                             {"f", AttributeType::kInt32, 127, -128},
                             {"g", AttributeType::kUInt32, 0, 65535},
                             {"h", AttributeType::kInt32, 2147483647.0, -2147483648.0},
                             {"i", AttributeType::kUInt32, 0, 4294967295.0},
                             {"j", AttributeType::kFloat32, 0.5, -0.5},
                             {"k", AttributeType::kInt32, 32767, -32768}};
  EXPECT_EQ(c.attributes.size(), std::size(expected));
  for (const auto& e : expected) {
    const Attribute* a = c.find_attribute(e.name);
    ASSERT_NE(a, nullptr) << e.name;
    EXPECT_EQ(int(a->type), int(e.type)) << e.name;
    EXPECT_EQ(a->values[0], e.v0) << e.name;
    EXPECT_EQ(a->values[1], e.v1) << e.name;
  }
  EXPECT_EQ(r.fields.size(), 17u);
}

// The same content (vertex after a face element and a list-only element, so that both must be
// skipped exactly) in the three encodings.
std::string mixed_binary(bool big) {
  auto f = [big](float v) { return big ? bytes_be(v) : bytes_le(v); };
  auto d = [big](double v) { return big ? bytes_be(v) : bytes_le(v); };
  auto i32 = [big](std::int32_t v) { return big ? bytes_be(v) : bytes_le(v); };
  auto u16 = [big](std::uint16_t v) { return big ? bytes_be(v) : bytes_le(v); };
  std::string s = std::string("ply\nformat ") +
                  (big ? "binary_big_endian" : "binary_little_endian") +
                  " 1.0\nelement face 2\nproperty list uchar int vertex_indices\nproperty uchar "
                  "flag\nelement material 1\nproperty list ushort double values\n"
                  "element vertex 2\nproperty float x\nproperty double y\nproperty int z\n"
                  "property float confidence\nend_header\n";
  s += std::string(1, '\3') + i32(0) + i32(1) + i32(0) + std::string(1, '\7');
  s += std::string(1, '\4') + i32(1) + i32(0) + i32(1) + i32(0) + std::string(1, '\0');
  s += u16(3) + d(1.0) + d(2.0) + d(3.0);
  s += f(0.5f) + d(-1.25) + i32(3) + f(0.75f);
  s += f(-4.0f) + d(1e-3) + i32(-9) + f(1.0f);
  return s;
}

TEST_F(PlyTest, SkipsListElementsInAllThreeEncodings) {
  const std::string ascii =
      "ply\nformat ascii 1.0\nelement face 2\nproperty list uchar int vertex_indices\n"
      "property uchar flag\nelement material 1\nproperty list ushort double values\n"
      "element vertex 2\nproperty float x\nproperty double y\nproperty int z\n"
      "property float confidence\nend_header\n3 0 1 0 7\n4 1 0 1 0 0\n3 1 2 3\n"
      "0.5 -1.25 3 0.75\n-4 0.001 -9 1\n";
  for (const auto& [name, content] : {std::pair<std::string, std::string>{"a.ply", ascii},
                                      {"le.ply", mixed_binary(false)},
                                      {"be.ply", mixed_binary(true)}}) {
    ReadReport r;
    const PointCloud c = read_ply(file(name, content), &r);
    ASSERT_EQ(c.size(), 2u) << name;
    EXPECT_EQ(c.positions[0], Eigen::Vector3d(0.5, -1.25, 3)) << name;
    EXPECT_EQ(c.positions[1], Eigen::Vector3d(-4, 1e-3, -9)) << name;
    EXPECT_EQ(c.confidences, (std::vector<float>{0.75f, 1.0f})) << name;
    EXPECT_EQ(r.warnings.size(), 2u) << name;  // face and material skipped, each reported
    EXPECT_TRUE(r.warnings.empty() || r.warnings[0].find("face") != std::string::npos);
  }
}

TEST_F(PlyTest, RangeGridBecomesTheOrganizedGrid) {
  const auto p = file("grid.ply",
                      "ply\nformat ascii 1.0\nobj_info num_cols 3\nobj_info num_rows 2\n"
                      "element vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                      "element range_grid 6\nproperty list uchar int vertex_indices\nend_header\n"
                      "0 0 0\n1 0 0\n0 1 0\n1 1 0\n1 0\n0\n1 1\n1 2\n0\n1 3\n");
  const PointCloud c = read_ply(p);
  ASSERT_EQ(c.grid.rows, 2);
  ASSERT_EQ(c.grid.cols, 3);
  EXPECT_EQ(c.grid.index, (std::vector<std::int32_t>{0, -1, 1, 2, -1, 3}));
  EXPECT_NO_THROW(c.check_consistent());
}

TEST_F(PlyTest, UnknownHeaderLinesAreSkippedWithAWarningNamingFileAndLine) {
  const auto p = file("bye.ply",
                      "ply\nformat ascii 1.0\nobj_info x 1\nbye\nelement vertex 1\n"
                      "property float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n");
  ReadReport r;
  const PointCloud c = read_ply(p, &r);
  EXPECT_EQ(c.size(), 1u);
  ASSERT_EQ(r.warnings.size(), 1u);
  EXPECT_NE(r.warnings[0].find("bye.ply: line 4"), std::string::npos) << r.warnings[0];
  EXPECT_NE(r.warnings[0].find("'bye'"), std::string::npos) << r.warnings[0];
}

TEST_F(PlyTest, NonFiniteVerticesAreDroppedAndCounted) {
  const auto p = file("nan.ply",
                      "ply\nformat ascii 1.0\nobj_info num_cols 2\nobj_info num_rows 2\n"
                      "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                      "element range_grid 4\nproperty list uchar int vertex_indices\nend_header\n"
                      "1 2 3\nnan 0 0\n4 5 inf\n1 0\n1 1\n1 2\n0\n");
  ReadReport r;
  const PointCloud c = read_ply(p, &r);
  EXPECT_EQ(c.size(), 1u);
  EXPECT_EQ(r.dropped_invalid, 2u);
  EXPECT_EQ(c.grid.index, (std::vector<std::int32_t>{0, -1, -1, -1}));
  ASSERT_FALSE(r.warnings.empty());
  EXPECT_NE(r.warnings.back().find("2 of 3"), std::string::npos) << r.warnings.back();
}

TEST_F(PlyTest, TriangleMeshReadsFacesAndFansPolygons) {
  const auto p =
      file("mesh.ply",
           "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float "
           "y\nproperty float z\nelement face 2\nproperty list uchar int vertex_indices\n"
           "end_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n4 0 1 2 3\n");
  const TriangleMesh m = read_triangle_mesh(p);
  EXPECT_EQ(m.vertices.size(), 4u);
  ASSERT_EQ(m.triangles.size(), 3u);
  EXPECT_EQ(m.triangles[2], (std::array<int, 3>{0, 2, 3}));
  const auto bad = file("badmesh.ply",
                        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float "
                        "y\nproperty float z\nelement face 1\nproperty list uchar int "
                        "vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n3 0 1 5\n");
  const std::string msg = input_error_of([&] { read_triangle_mesh(bad); });
  EXPECT_NE(msg.find("line 13"), std::string::npos) << msg;
  EXPECT_NE(msg.find("out of range"), std::string::npos) << msg;
  // A mesh cannot drop vertices: a non-finite one is an error naming its line.
  const auto nan_mesh = file("nanmesh.ply",
                             "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty "
                             "float y\nproperty float z\nelement face 1\nproperty list uchar int "
                             "vertex_indices\nend_header\n0 0 0\n1 nan 0\n1 1 0\n3 0 1 2\n");
  const std::string msg2 = input_error_of([&] { read_triangle_mesh(nan_mesh); });
  EXPECT_NE(msg2.find("line 11"), std::string::npos) << msg2;
  EXPECT_NE(msg2.find("vertex 1 has a non-finite coordinate"), std::string::npos) << msg2;
}

struct Malformed {
  const char* name;
  std::string content;
  std::vector<std::string> expected;  // substrings of the message
};

std::string xyz_header(const std::string& count, const std::string& format = "ascii") {
  return "ply\nformat " + format + " 1.0\nelement vertex " + count +
         "\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
}

TEST_F(PlyTest, MalformedFilesGiveInputErrorsWithPlace) {
  const std::vector<Malformed> cases = {
      {"empty", "", {"empty file"}},
      {"not_ply", "PLY\nformat ascii 1.0\n", {"line 1", "expected 'ply'"}},
      {"no_end_header", "ply\nformat ascii 1.0\nelement vertex 1\n", {"end_header"}},
      {"no_format", "ply\nelement vertex 0\nend_header\n", {"format"}},
      {"bad_format",
       "ply\nformat binary_middle_endian 1.0\nend_header\n",
       {"line 2", "binary_middle_endian"}},
      {"bad_type",
       "ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n0\n",
       {"line 4", "float128"}},
      {"property_first",
       "ply\nformat ascii 1.0\nproperty float x\nend_header\n",
       {"line 3", "before any 'element'"}},
      {"bad_count", "ply\nformat ascii 1.0\nelement vertex -5\nend_header\n", {"line 3"}},
      {"vertex_without_properties",
       "ply\nformat binary_little_endian 1.0\nelement vertex 2000000000\nend_header\n",
       {"line 3", "no scalar property x"}},
      {"no_vertex", "ply\nformat ascii 1.0\nelement face 0\nend_header\n", {"element vertex"}},
      {"missing_z",
       "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
       "end_header\n1 2\n",
       {"line 3", "no scalar property z"}},
      {"truncated_ascii",
       xyz_header("3") + "1.000000 2.000000 3.000000\n4.0000 5.0000 6.0000\n",
       {"line 10", "end of file", "of 3"}},
      {"short_line",
       xyz_header("2") + "1.000000 2.000000\n4.000000 5.000000 6.000000\n",
       {"line 8", "ends early", "'z'"}},
      {"long_line", xyz_header("2") + "1 2 3 4\n4 5 6\n", {"line 8", "end of the line"}},
      {"not_a_number", xyz_header("1") + "1 abc 3\n", {"line 8", "'abc'", "float32"}},
      {"lying_count_ascii",
       xyz_header("1000000000") + "1 2 3\n",
       {"line 3", "1000000000", "bytes follow the header"}},
      {"lying_count_binary",
       xyz_header("4000000000", "binary_little_endian") + std::string(12, '\0'),
       {"4000000000", "bytes follow the header"}},
      {"truncated_binary",
       xyz_header("2", "binary_little_endian") + bytes_le(1.f) + bytes_le(2.f) + bytes_le(3.f) +
           bytes_le(4.f) + bytes_le(5.f) + "\1\2",
       {"line 3", "needs at least 24 bytes", "only 22 bytes follow the header"}},
      {"uchar_out_of_range",
       "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
       "property float z\nproperty uchar red\nend_header\n1 2 3 300\n",
       {"line 9", "out of range", "uint8"}},
      {"huge_list_binary",
       xyz_header("1", "binary_little_endian") + "element_placeholder",  // replaced below
       {}},
      {"grid_index_out_of_range",
       "ply\nformat ascii 1.0\nobj_info num_cols 1\nobj_info num_rows 1\nelement vertex 1\n"
       "property float x\nproperty float y\nproperty float z\nelement range_grid 1\n"
       "property list uchar int vertex_indices\nend_header\n1 2 3\n1 7\n",
       {"line 13", "vertex index 7", "out of range"}},
  };
  for (const auto& c : cases) {
    if (std::string(c.name) == "huge_list_binary") continue;
    const std::string msg =
        input_error_of([&] { read_ply(file(std::string(c.name) + ".ply", c.content)); });
    EXPECT_NE(msg.find(std::string(c.name) + ".ply"), std::string::npos) << c.name << ": " << msg;
    for (const auto& e : c.expected)
      EXPECT_NE(msg.find(e), std::string::npos) << c.name << ": '" << e << "' not in: " << msg;
  }
  // A binary list whose declared length cannot fit in the rest of the file.
  const std::string huge =
      "ply\nformat binary_little_endian 1.0\nelement vertex 1\n"
      "property float x\nproperty float y\nproperty float z\n"
      "element face 1\nproperty list uint int vertex_indices\nend_header\n" +
      bytes_le(1.f) + bytes_le(2.f) + bytes_le(3.f) + bytes_le(std::uint32_t{4000000000u}) +
      bytes_le(std::int32_t{0});
  const std::string msg = input_error_of([&] { read_ply(file("huge_list.ply", huge)); });
  EXPECT_NE(msg.find("4000000000 entries"), std::string::npos) << msg;
  EXPECT_NE(msg.find("byte"), std::string::npos) << msg;
}

TEST_F(PlyTest, FailedWriteLeavesNoPartialFile) {
  const PointCloud c = test::full_cloud(50, 3);  // seed 3
  // The target is an existing folder: everything is written, then the final rename fails.
  std::filesystem::create_directory(dir_ / "out.ply");
  EXPECT_THROW(write_ply(dir_ / "out.ply", c), IoError);
  std::size_t entries = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir_)) {
    ++entries;
    EXPECT_EQ(e.path().filename(), "out.ply");
  }
  EXPECT_EQ(entries, 1u);
  // An existing good file survives a failed overwrite untouched.
  write_ply(dir_ / "good.ply", c);
  const std::string before = test::read_bytes(dir_ / "good.ply");
  PointCloud broken = c;
  broken.normals.pop_back();  // inconsistent: the writer refuses before touching anything
  EXPECT_THROW(write_ply(dir_ / "good.ply", broken), std::logic_error);
  EXPECT_EQ(test::read_bytes(dir_ / "good.ply"), before);
}

}  // namespace
}  // namespace scanclean

// Streaming reads by record ranges (point_stream.h) against the whole-file readers.
#include "scanclean/io/point_stream.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <random>

#include "io_test_util.h"
#include "scanclean/io/point_cloud_io.h"
#include "support/synthetic.h"

namespace scanclean {
namespace {

namespace fs = std::filesystem;

PointCloud random_cloud(std::size_t n, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-3.0, 3.0);
  std::uniform_int_distribution<int> c(0, 255);
  PointCloud cloud;
  for (std::size_t i = 0; i < n; ++i) {
    cloud.positions.push_back(test::draw_point(rng, u, u, u));
    cloud.normals.emplace_back(
        Eigen::Vector3f(static_cast<float>(u(rng)), 1.0f, 0.5f).normalized());
    cloud.confidences.push_back(static_cast<float>(i % 7) / 7.0f);
    cloud.intensities.push_back(static_cast<float>(i));
    cloud.colors.push_back({static_cast<std::uint8_t>(c(rng)), static_cast<std::uint8_t>(c(rng)),
                            static_cast<std::uint8_t>(c(rng)), 255});
  }
  return cloud;
}

fs::path temp_dir(const std::string& name) {
  const fs::path d = fs::temp_directory_path() /
                     ("scanclean_point_stream_" + name + "_" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d;
}

void expect_same(const PointCloud& a, const PointCloud& b, std::size_t a0 = 0) {
  ASSERT_LE(a0 + b.size(), a.size());
  for (std::size_t i = 0; i < b.size(); ++i) {
    ASSERT_EQ(a.positions[a0 + i], b.positions[i]) << "point " << i;
    if (a.has_normals()) {
      ASSERT_EQ(a.normals[a0 + i], b.normals[i]);
    }
    if (a.has_confidences()) {
      ASSERT_EQ(a.confidences[a0 + i], b.confidences[i]);
    }
    if (a.has_intensities()) {
      ASSERT_EQ(a.intensities[a0 + i], b.intensities[i]);
    }
    if (a.has_colors()) {
      ASSERT_EQ(a.colors[a0 + i], b.colors[i]);
    }
  }
  ASSERT_EQ(a.attributes.size(), b.attributes.size());
  for (std::size_t k = 0; k < a.attributes.size(); ++k) {
    ASSERT_EQ(a.attributes[k].name, b.attributes[k].name);
    ASSERT_EQ(a.attributes[k].type, b.attributes[k].type) << a.attributes[k].name;
    for (std::size_t i = 0; i < b.size(); ++i)
      ASSERT_EQ(a.attributes[k].values[a0 + i], b.attributes[k].values[i])
          << a.attributes[k].name << ", point " << i;
  }
}

TEST(PointStream, BinaryPlyRangesMatchTheWholeFileReader) {
  const fs::path d = temp_dir("ply");
  const PointCloud cloud = random_cloud(1003, 7);
  write_ply(d / "c.ply", cloud);
  const PointCloud whole = read_ply(d / "c.ply");
  const auto s = PointStream::open(d / "c.ply");
  ASSERT_EQ(s->size(), 1003u);
  EXPECT_TRUE(s->has_normals());
  EXPECT_TRUE(s->has_confidences());
  EXPECT_TRUE(s->has_intensities());
  EXPECT_TRUE(s->has_colors());
  PointCloud part;
  std::vector<std::uint64_t> rec;
  s->read(0, 1003, part, &rec);
  ASSERT_EQ(part.size(), whole.size());
  expect_same(whole, part);
  // Uneven chunks, in order, cover every record once.
  std::uint64_t next = 0;
  s->for_each_chunk(0, s->size(), 97,
                    [&](const PointCloud& c, const std::vector<std::uint64_t>& r) {
                      ASSERT_EQ(r.size(), c.size());
                      ASSERT_FALSE(r.empty());
                      EXPECT_EQ(r.front(), next);
                      expect_same(whole, c, next);
                      next = r.back() + 1;
                    });
  EXPECT_EQ(next, 1003u);
  // A range past the end is clipped.
  s->read(1000, 50, part, &rec);
  EXPECT_EQ(part.size(), 3u);
  EXPECT_EQ(rec.back(), 1002u);
  fs::remove_all(d);
}

TEST(PointStream, SplitsCoverEveryRecordOnceForAnyRankCount) {
  for (int ranks : {1, 2, 3, 4, 7}) {
    std::uint64_t at = 0;
    for (int r = 0; r < ranks; ++r) {
      const auto [b, e] = PointStream::split(1003, r, ranks);
      EXPECT_EQ(b, at);
      EXPECT_GE(e, b);
      EXPECT_LE(e - b, 1003u / ranks + 1);
      at = e;
    }
    EXPECT_EQ(at, 1003u);
  }
}

TEST(PointStream, BinaryPcdMatchesTheWholeFileReader) {
  const fs::path d = temp_dir("pcd");
  PointCloud cloud = random_cloud(500, 11);
  cloud.confidences.clear();  // the PCD writer's confidence field is read too, but keep it plain
  write_pcd(d / "c.pcd", cloud, "binary");
  const PointCloud whole = read_pcd(d / "c.pcd");
  const auto s = PointStream::open(d / "c.pcd");
  ASSERT_EQ(s->size(), 500u);
  EXPECT_TRUE(s->has_colors());
  PointCloud part;
  s->read(123, 200, part);
  ASSERT_EQ(part.size(), 200u);
  expect_same(whole, part, 123);
  fs::remove_all(d);
}

// The fields map to the cloud as the whole-file readers map them: normals named normal_x ...,
// colours stored as floats in [0, 1], and every other field (of every type, a second field of
// one name left out) as an attribute of its name and type, in file order.
TEST(PointStream, FieldsMapAsInTheWholeFileReaders) {
  const fs::path d = temp_dir("fields");
  std::string ply =
      "ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\n"
      "property float y\nproperty float z\nproperty uchar classification\n"
      "property float normal_x\nproperty float normal_y\nproperty float normal_z\n"
      "property float red\nproperty float green\nproperty float blue\nproperty double gps_time\n"
      "property short scan\nproperty ushort ret\nproperty char tag\nproperty uchar "
      "classification\nend_header\n";
  for (int i = 0; i < 4; ++i) {
    const float f[3] = {0.5f * i, 1.0f, -2.0f};
    for (float v : f) ply += test::bytes_le(v);
    ply += std::string(1, static_cast<char>(2 + i));
    for (float v : {0.0f, 0.6f, 0.8f}) ply += test::bytes_le(v);
    for (float v : {0.25f * i, 1.0f, 0.5f}) ply += test::bytes_le(v);
    ply += test::bytes_le(1.0e9 + 0.125 * i);
    ply += test::bytes_le(static_cast<std::int16_t>(-300 + i));
    ply += test::bytes_le(static_cast<std::uint16_t>(60000 + i));
    ply += std::string(1, static_cast<char>(-5 - i));
    ply += std::string(1, static_cast<char>(99));
  }
  test::write_bytes(d / "f.ply", ply);
  const PointCloud whole = read_ply(d / "f.ply");
  const auto s = PointStream::open(d / "f.ply");
  EXPECT_TRUE(s->has_normals());
  EXPECT_TRUE(s->has_colors());
  const std::vector<std::pair<std::string, AttributeType>> attrs = {
      {"classification", AttributeType::kUInt8},
      {"gps_time", AttributeType::kFloat64},
      {"scan", AttributeType::kInt32},
      {"ret", AttributeType::kUInt32},
      {"tag", AttributeType::kInt32}};
  EXPECT_EQ(s->attributes(), attrs);
  PointCloud part;
  s->read(1, 3, part);
  ASSERT_EQ(part.size(), 3u);
  expect_same(whole, part, 1);
  EXPECT_EQ(part.colors[0], (std::array<std::uint8_t, 4>{64, 255, 128, 255}));
  EXPECT_EQ(part.attributes[0].values[0], 3.0);  // the first "classification"

  // PCD: COUNT 1 fields only, "_" is padding, rgb packed, the rest attributes.
  PointCloud cloud = random_cloud(50, 3);
  cloud.confidences.clear();
  std::vector<double> label(50), curvature(50);
  for (std::size_t i = 0; i < 50; ++i) {
    label[i] = static_cast<double>(i * 1000);
    curvature[i] = 0.5 / static_cast<double>(i + 1);
  }
  cloud.set_attribute("label", AttributeType::kUInt32, label);
  cloud.set_attribute("curvature", AttributeType::kFloat32, curvature);
  write_pcd(d / "c.pcd", cloud, "binary");
  const PointCloud pcd_whole = read_pcd(d / "c.pcd");
  const auto p = PointStream::open(d / "c.pcd");
  ASSERT_EQ(p->attributes().size(), pcd_whole.attributes.size());
  ASSERT_FALSE(p->attributes().empty());
  p->read(10, 30, part);
  ASSERT_EQ(part.size(), 30u);
  expect_same(pcd_whole, part, 10);
  fs::remove_all(d);
}

TEST(PointStream, BigEndianPlyAndNonFinitePointsDropped) {
  const fs::path d = temp_dir("be");
  std::string bytes =
      "ply\nformat binary_big_endian 1.0\ncomment x\nelement vertex 3\nproperty double x\n"
      "property double y\nproperty float z\nproperty uchar flag\nend_header\n";
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double xs[3] = {1.5, nan, -2.25};
  for (int i = 0; i < 3; ++i) {
    bytes += test::bytes_be(xs[i]);
    bytes += test::bytes_be(0.5 * i);
    bytes += test::bytes_be(static_cast<float>(i) + 0.25f);
    bytes += std::string(1, static_cast<char>(i));
  }
  test::write_bytes(d / "be.ply", bytes);
  const auto s = PointStream::open(d / "be.ply");
  EXPECT_EQ(s->size(), 3u);
  EXPECT_EQ(s->record_bytes(), 21u);
  PointCloud c;
  std::vector<std::uint64_t> rec;
  s->read(0, 3, c, &rec);
  ASSERT_EQ(c.size(), 2u);
  EXPECT_EQ(rec, (std::vector<std::uint64_t>{0, 2}));
  EXPECT_EQ(c.positions[0], Eigen::Vector3d(1.5, 0.0, 0.25));
  EXPECT_EQ(c.positions[1], Eigen::Vector3d(-2.25, 1.0, 2.25));
  fs::remove_all(d);
}

TEST(PointStream, RefusesWhatItCannotStreamWithAClearError) {
  const fs::path d = temp_dir("bad");
  write_ply(d / "a.ply", random_cloud(5, 3), PlyEncoding::kAscii);
  write_pcd(d / "c.pcd", random_cloud(5, 3), "binary_compressed");
  auto message = [](const fs::path& p) {
    try {
      PointStream::open(p);
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message(d / "a.ply").find("ASCII PLY is not streamable"), std::string::npos);
  EXPECT_NE(message(d / "c.pcd").find("binary_compressed PCD is not streamable"),
            std::string::npos);
  EXPECT_FALSE(PointStream::streamable(d / "a.ply"));
  // Truncated: the header declares more records than the file holds.
  write_ply(d / "t.ply", random_cloud(10, 3));
  const std::string full = test::read_bytes(d / "t.ply");
  test::write_bytes(d / "t.ply", full.substr(0, full.size() - 5));
  const std::string m = message(d / "t.ply");
  EXPECT_NE(m.find("t.ply"), std::string::npos) << m;
  EXPECT_NE(m.find("truncated"), std::string::npos) << m;
  EXPECT_THROW(PointStream::open(d / "missing.ply"), IoError);
  fs::remove_all(d);
}

}  // namespace
}  // namespace scanclean

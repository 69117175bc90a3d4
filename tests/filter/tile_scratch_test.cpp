// The scratch files of a tiled run (filter/src/tile_scratch.h): records read back as written
// with every array a cloud can carry, a partial record refused naming the file, the writer's
// files per tile, and the cleanup that removes every process's files only when a run fails.
#include "../../filter/src/tile_scratch.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "scanclean/core/errors.h"
#include "tiled_test_support.h"

namespace scanclean::detail {
namespace {

namespace fs = std::filesystem;

using TempDir = test::ScratchDir;

// n points with every array and two attributes, values drawn at random (seeded).
PointCloud full_cloud(std::size_t n, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1e3, 1e3);
  std::uniform_real_distribution<float> f(0.0f, 1.0f);
  std::uniform_int_distribution<int> byte(0, 255);
  PointCloud c;
  c.attributes = {{"gps_time", AttributeType::kFloat64, {}}, {"class", AttributeType::kUInt8, {}}};
  for (std::size_t i = 0; i < n; ++i) {
    c.positions.emplace_back(u(rng), u(rng), u(rng));
    c.normals.emplace_back(f(rng), f(rng), f(rng));
    c.confidences.push_back(f(rng));
    c.intensities.push_back(f(rng) * 4000.0f);
    c.colors.push_back({static_cast<std::uint8_t>(byte(rng)), static_cast<std::uint8_t>(byte(rng)),
                        static_cast<std::uint8_t>(byte(rng)), 255});
    c.attributes[0].values.push_back(u(rng) * 1e6);
    c.attributes[1].values.push_back(static_cast<double>(byte(rng)));
  }
  return c;
}

ScratchColumns all_columns(const PointCloud& c) {
  ScratchColumns cols;
  cols.normals = cols.confidences = cols.intensities = cols.colors = true;
  for (const Attribute& a : c.attributes) cols.attributes.emplace_back(a.name, a.type);
  return cols;
}

void write_file(const fs::path& file, const std::string& bytes) {
  std::ofstream out(file, std::ios::binary);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

TEST(TileScratch, RecordsReadBackAsWrittenWithEveryArray) {
  const TempDir dir("roundtrip");
  const PointCloud c = full_cloud(500, 3);
  const ScratchColumns cols = all_columns(c);
  EXPECT_EQ(cols.bytes(), 8u + 24 + 12 + 4 + 4 + 4 + 16);
  std::string bytes;
  std::vector<std::uint64_t> sent;
  for (std::size_t i = 0; i < c.size(); ++i) {
    // Record numbers far apart, every third marked as a kernel site.
    const std::uint64_t rec = (i * 1000003 + 17) | (i % 3 == 0 ? kSiteBit : 0);
    put_point(bytes, c, i, rec, cols);
    sent.push_back(rec);
  }
  ASSERT_EQ(bytes.size(), c.size() * cols.bytes());
  write_file(dir.path / "t.pts", bytes);
  PointCloud back;
  std::vector<std::uint64_t> rec;
  read_points(dir.path / "t.pts", cols, back, rec);
  EXPECT_EQ(rec, sent);
  EXPECT_EQ(back.positions, c.positions);
  EXPECT_EQ(back.normals, c.normals);
  EXPECT_EQ(back.confidences, c.confidences);
  EXPECT_EQ(back.intensities, c.intensities);
  EXPECT_EQ(back.colors, c.colors);
  ASSERT_EQ(back.attributes.size(), 2u);
  for (std::size_t a = 0; a < 2; ++a) {
    EXPECT_EQ(back.attributes[a].name, c.attributes[a].name);
    EXPECT_EQ(back.attributes[a].type, c.attributes[a].type);
    EXPECT_EQ(back.attributes[a].values, c.attributes[a].values);
  }
  // A second file appends to the same cloud (a tile's files of several processes).
  read_points(dir.path / "t.pts", cols, back, rec);
  EXPECT_EQ(back.size(), 2 * c.size());
  EXPECT_EQ(back.attributes[1].values.size(), 2 * c.size());
}

// A chunk that lacks an array other records carry (a source whose chunks disagree) is refused
// before any of its records is written: its records would be read past their arrays' ends.
TEST(TileScratch, AChunkWithoutAnArrayOtherRecordsCarryIsRefused) {
  const PointCloud full = full_cloud(10, 7);
  const ScratchColumns cols = all_columns(full);
  EXPECT_NO_THROW(check_columns(full, cols));
  const std::pair<const char*, std::function<void(PointCloud&)>> cuts[] = {
      {"normals", [](PointCloud& c) { c.normals.clear(); }},
      {"confidences", [](PointCloud& c) { c.confidences.pop_back(); }},
      {"intensities", [](PointCloud& c) { c.intensities.clear(); }},
      {"colours", [](PointCloud& c) { c.colors.clear(); }},
      {"attribute values", [](PointCloud& c) { c.attributes[1].values.pop_back(); }},
      {"other attributes", [](PointCloud& c) { c.attributes.pop_back(); }},
  };
  for (const auto& [what, cut] : cuts) {
    PointCloud c = full;
    cut(c);
    try {
      check_columns(c, cols);
      ADD_FAILURE() << "a chunk without its " << what << " passed";
    } catch (const std::logic_error& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    }
  }
  // Arrays the other records do not carry are left out of the records: no error.
  ScratchColumns positions_only;
  for (const Attribute& a : full.attributes) positions_only.attributes.emplace_back(a.name, a.type);
  EXPECT_NO_THROW(check_columns(full, positions_only));
}

TEST(TileScratch, PositionsOnlyTakeThirtyTwoBytesARecord) {
  const TempDir dir("plain");
  PointCloud c;
  c.positions = {{1, 2, 3}, {-4, 5.5, 1e-9}};
  const ScratchColumns cols;
  EXPECT_EQ(cols.bytes(), 32u);
  std::string bytes;
  put_point(bytes, c, 1, 9, cols);
  put_point(bytes, c, 0, 4, cols);
  ASSERT_EQ(bytes.size(), 64u);
  write_file(dir.path / "p.pts", bytes);
  PointCloud back;
  std::vector<std::uint64_t> rec;
  read_points(dir.path / "p.pts", cols, back, rec);
  EXPECT_EQ(rec, (std::vector<std::uint64_t>{9, 4}));
  EXPECT_EQ(back.positions, (std::vector<Eigen::Vector3d>{c.positions[1], c.positions[0]}));
  EXPECT_FALSE(back.has_normals());
  EXPECT_FALSE(back.has_colors());
}

TEST(TileScratch, APartialRecordIsAnErrorNamingTheFileAndAMissingFileHoldsNothing) {
  const TempDir dir("partial");
  const PointCloud c = full_cloud(3, 4);
  const ScratchColumns cols = all_columns(c);
  std::string bytes;
  for (std::size_t i = 0; i < 3; ++i) put_point(bytes, c, i, i, cols);
  bytes.pop_back();
  const fs::path file = dir.path / "cut.pts";
  write_file(file, bytes);
  PointCloud back;
  std::vector<std::uint64_t> rec;
  try {
    read_points(file, cols, back, rec);
    ADD_FAILURE() << "a partial record was read";
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find(file.string()), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("partial record"), std::string::npos) << e.what();
  }
  read_points(dir.path / "none.pts", cols, back, rec);
  EXPECT_EQ(back.size(), 0u);
  EXPECT_TRUE(rec.empty());
}

TEST(TileScratch, TheWriterKeepsEachTilesRecordsInOrderInItsOwnFile) {
  const TempDir dir("writer");
  const PointCloud c = full_cloud(3000, 5);
  const ScratchColumns cols = all_columns(c);
  // Four tiles; tile 2 gets nothing. Buffers of a few records, so most records pass a flush.
  ScratchWriter w(dir.path, 4, 3, 5 * cols.bytes());
  std::vector<std::vector<std::uint64_t>> sent(4);
  for (std::size_t i = 0; i < c.size(); ++i)
    for (const std::size_t tile : {i % 2 == 0 ? std::size_t{0} : std::size_t{1}, std::size_t{3}}) {
      if (tile == 3 && i % 7 != 0) continue;
      w.put(tile, c, i, i, cols);
      sent[tile].push_back(i);
    }
  w.finish();
  EXPECT_FALSE(fs::exists(scratch_file(dir.path, 2, 3)));
  for (const std::size_t tile : {0, 1, 3}) {
    const fs::path file = scratch_file(dir.path, tile, 3);
    ASSERT_TRUE(fs::exists(file)) << file;
    EXPECT_EQ(fs::file_size(file), sent[tile].size() * cols.bytes());
    PointCloud back;
    std::vector<std::uint64_t> rec;
    read_points(file, cols, back, rec);
    EXPECT_EQ(rec, sent[tile]) << "tile " << tile;
    for (std::size_t k = 0; k < rec.size(); ++k)
      ASSERT_EQ(back.positions[k], c.positions[rec[k]]) << "tile " << tile << ", record " << k;
  }
  EXPECT_EQ(scratch_file(dir.path, 12, 3).filename(), "tile000012.r0003.pts");
}

TEST(TileScratch, AWriterThatCannotCreateItsFileNamesIt) {
  const TempDir dir("nofolder");
  const PointCloud c = full_cloud(2, 6);
  const ScratchColumns cols = all_columns(c);
  ScratchWriter w(dir.path / "missing", 1, 0, 1);  // flushes at the first record
  try {
    w.put(0, c, 0, 0, cols);
    ADD_FAILURE() << "a scratch file was written into a missing folder";
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find((dir.path / "missing").string()), std::string::npos)
        << e.what();
  }
}

TEST(TileScratch, TheCleanupRemovesEveryProcesssFilesOnlyWhenTheRunFails) {
  const TempDir dir("cleanup");
  auto make_files = [&] {
    for (std::size_t tile = 0; tile < 3; ++tile)
      for (int rank = 0; rank < 2; ++rank) write_file(scratch_file(dir.path, tile, rank), "x");
    write_file(dir.path / "other.txt", "not a scratch file");
  };
  auto count = [&] {
    std::size_t n = 0;
    for (auto it = fs::directory_iterator(dir.path); it != fs::directory_iterator(); ++it) ++n;
    return n;
  };
  make_files();
  { const ScratchCleanup cleanup(dir.path, 3, 2); }
  EXPECT_EQ(count(), 7u) << "a run that ended normally lost its files";
  try {
    const ScratchCleanup cleanup(dir.path, 3, 2);
    throw std::runtime_error("the run failed");
  } catch (const std::runtime_error&) {
  }
  EXPECT_EQ(count(), 1u);
  EXPECT_TRUE(fs::exists(dir.path / "other.txt"));
}

}  // namespace
}  // namespace scanclean::detail

// The streamed PLY writer (io/ply_stream_writer.h): pieces appended, and room reserved for
// other processes to write in place (scanclean-mpi), read back as the one cloud they make; the
// target untouched until finish().
#include "scanclean/io/ply_stream_writer.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <vector>

#include "io_test_util.h"
#include "scanclean/io/ply.h"
#include "support/data_paths.h"

namespace scanclean {
namespace {

namespace fs = std::filesystem;

class PlyStreamWriterTest : public ::testing::Test {
 protected:
  void SetUp() override { dir_ = test::make_temp_dir("ply_stream"); }
  void TearDown() override { fs::remove_all(dir_); }
  // Points [b, e) of c.
  static PointCloud piece(const PointCloud& c, std::size_t b, std::size_t e) {
    std::vector<std::size_t> idx;
    for (std::size_t i = b; i < e; ++i) idx.push_back(i);
    return select(c, idx);
  }
  // The files in dir_ other than `keep`.
  std::vector<std::string> others(const std::string& keep) const {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(dir_))
      if (e.path().filename() != keep) names.push_back(e.path().filename().string());
    return names;
  }
  fs::path dir_;
};

TEST_F(PlyStreamWriterTest, PiecesAppendedReadBackAsOneCloud) {
  const PointCloud c = test::full_cloud(1000, 5);
  const fs::path path = dir_ / "out.ply";
  {
    PlyStreamWriter w(path, ply_layout_of(c, false), "a provenance line");
    w.append(piece(c, 0, 300));
    w.append(piece(c, 300, 300));  // an empty piece
    w.append_encoded(encode_ply_vertices(piece(c, 300, 1000), w.layout()), 700);
    EXPECT_EQ(w.points(), 1000u);
    EXPECT_FALSE(fs::exists(path)) << "visible before finish()";
    w.finish();
  }
  test::expect_same_cloud(c, read_ply(path));
  EXPECT_NE(test::read_bytes(path).find("comment a provenance line\n"), std::string::npos);
  EXPECT_TRUE(others("out.ply").empty()) << "a temporary file was left";
}

// Process 0 reserves room for the points of the other processes, which write them in place
// (write_at) at the offsets it gave; pieces may be appended after the room.
TEST_F(PlyStreamWriterTest, RoomReservedIsWrittenInPlaceByOthers) {
  const PointCloud c = test::full_cloud(900, 6);
  const fs::path path = dir_ / "out.ply";
  {
    PlyStreamWriter w(path, ply_layout_of(c, false));
    w.append(piece(c, 0, 200));
    const std::string middle = encode_ply_vertices(piece(c, 200, 650), w.layout());
    const std::string first = middle.substr(0, middle.size() / 3);  // two writers, any order
    const std::string second = middle.substr(first.size());
    const std::uint64_t at = w.reserve(middle.size(), 450);
    EXPECT_EQ(at + middle.size(), fs::file_size(w.temporary()));
    write_at(w.temporary(), at + first.size(), second);
    write_at(w.temporary(), at, first);
    w.append(piece(c, 650, 900));
    EXPECT_EQ(w.points(), 900u);
    w.finish();
  }
  test::expect_same_cloud(c, read_ply(path));
  EXPECT_TRUE(others("out.ply").empty()) << "a temporary file was left";
}

TEST_F(PlyStreamWriterTest, WithoutFinishTheTargetIsUntouched) {
  const PointCloud c = test::full_cloud(50, 7);
  const fs::path path = dir_ / "out.ply";
  test::write_bytes(path, "the old contents");
  {
    PlyStreamWriter w(path, ply_layout_of(c, false));
    w.append(c);
    w.reserve(1000, 10);
  }
  EXPECT_EQ(test::read_bytes(path), "the old contents");
  EXPECT_TRUE(others("out.ply").empty()) << "a temporary file was left";
}

TEST_F(PlyStreamWriterTest, WritingInPlaceIntoAMissingFileNamesIt) {
  const fs::path missing = dir_ / "gone.ply.tmp";
  try {
    write_at(missing, 0, "abc");
    FAIL() << "no error";
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find(missing.string()), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace scanclean

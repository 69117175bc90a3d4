#include "scanclean/mesh/mesh_io.h"

#include <gtest/gtest.h>

#include <fstream>

#include "scanclean/core/errors.h"
#include "scanclean/io/triangle_mesh_io.h"
#include "support/data_paths.h"

namespace scanclean {
namespace {

TriangleMesh square_with_unused_vertex() {
  TriangleMesh m;
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {7, 7, 7}, {1, 1, 0.25}, {0, 1, 0}};
  m.triangles = {{0, 1, 3}, {0, 3, 4}};
  return m;
}

TEST(MeshIoTest, BinaryAndAsciiRoundTripThroughTheMeshReader) {
  const auto dir = test::make_temp_dir("mesh_io");
  const TriangleMesh m = square_with_unused_vertex();
  for (auto enc : {PlyEncoding::kBinaryLittleEndian, PlyEncoding::kAscii}) {
    MeshWriteOptions o;
    o.encoding = enc;
    o.comments = {"a comment\nwith a newline"};
    const auto path = dir / (enc == PlyEncoding::kAscii ? "a.ply" : "b.ply");
    write_mesh_ply(path, m, o);
    const TriangleMesh back = read_triangle_mesh(path);
    ASSERT_EQ(back.vertices.size(), m.vertices.size());
    ASSERT_EQ(back.triangles.size(), m.triangles.size());
    for (std::size_t i = 0; i < m.vertices.size(); ++i)
      EXPECT_LT((back.vertices[i] - m.vertices[i]).norm(), 1e-6);
    EXPECT_EQ(back.triangles, m.triangles);
  }
}

TEST(MeshIoTest, DropUnreferencedRenumbersTheTriangles) {
  const auto dir = test::make_temp_dir("mesh_io");
  MeshWriteOptions o;
  o.drop_unreferenced = true;
  write_mesh_ply(dir / "m.ply", square_with_unused_vertex(), o);
  const TriangleMesh back = read_triangle_mesh(dir / "m.ply");
  ASSERT_EQ(back.vertices.size(), 4u);
  EXPECT_EQ(back.triangles[0], (std::array<int, 3>{0, 1, 2}));
  EXPECT_EQ(back.triangles[1], (std::array<int, 3>{0, 2, 3}));
  EXPECT_LT((back.vertices[2] - Eigen::Vector3d(1, 1, 0.25)).norm(), 1e-7);
}

TEST(MeshIoTest, OnlyPlyIsAcceptedAndNothingIsWrittenOtherwise) {
  const auto dir = test::make_temp_dir("mesh_io");
  EXPECT_THROW(write_mesh_ply(dir / "m.obj", square_with_unused_vertex()), OptionError);
  EXPECT_FALSE(std::filesystem::exists(dir / "m.obj"));
  EXPECT_THROW(write_mesh_ply(dir / "missing" / "m.ply", square_with_unused_vertex()), IoError);
  EXPECT_TRUE(is_mesh_output_path("A.PLY"));
  EXPECT_FALSE(is_mesh_output_path("a.pcd"));
}

TEST(MeshIoTest, RecordedKernelSizeIsReadFromTheHeaderOnly) {
  const auto dir = test::make_temp_dir("mesh_io");
  auto write = [&](const std::string& name, const std::string& text) {
    std::ofstream(dir / name) << text;
    return dir / name;
  };
  EXPECT_DOUBLE_EQ(
      *recorded_kernel_size(write("a.ply",
                                  "ply\nformat ascii 1.0\ncomment scanclean 0.1.0 filter h=0.0027m "
                                  "noise_sigma=0.0001\nelement vertex 0\nend_header\n")),
      0.0027);
  EXPECT_DOUBLE_EQ(*recorded_kernel_size(write("b.ply",
                                               "ply\nformat ascii 1.0\nobj_info filter_h=0.5\n"
                                               "element vertex 0\nend_header\n")),
                   0.5);
  EXPECT_FALSE(recorded_kernel_size(write("c.ply",
                                          "ply\nformat ascii 1.0\ncomment hh=3 h=x\nelement "
                                          "vertex 0\nend_header\ncomment h=1\n")));
  EXPECT_DOUBLE_EQ(*recorded_kernel_size(write("e.ply",
                                               "ply\nformat ascii 1.0\ncomment scanclean filter "
                                               "h 2.5 mm, noise 0.1 mm\nelement vertex 0\n"
                                               "end_header\n")),
                   0.0025);
  EXPECT_FALSE(recorded_kernel_size(write("f.ply",
                                          "ply\nformat ascii 1.0\ncomment h=3furlongs\n"
                                          "element vertex 0\nend_header\n")));
  EXPECT_FALSE(recorded_kernel_size(write("d.xyz", "comment h=1\n")));
  EXPECT_FALSE(recorded_kernel_size(dir / "none.ply"));
}

}  // namespace
}  // namespace scanclean

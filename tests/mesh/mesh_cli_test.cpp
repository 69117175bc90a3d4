// `scanclean mesh` and `filter --mesh` end to end: child processes, exit codes, files read back.

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "scanclean/io/point_cloud_io.h"
#include "scanclean/io/triangle_mesh_io.h"
#include "support/data_paths.h"
#include "support/program_run.h"
#include "support/synthetic.h"

#ifdef SCANCLEAN_PROGRAM

namespace fs = std::filesystem;

namespace scanclean {
namespace {

using test::ProgramRun;
using test::slurp;

ProgramRun run(const std::vector<std::string>& args, const fs::path& dir) {
  return test::run_program(SCANCLEAN_PROGRAM, args, dir);
}

bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

TEST(MeshCliTest, MeshWritesAnInterpolatingMeshAndSummarises) {
  const auto dir = test::make_temp_dir("mesh_cli");
  const PointCloud sphere = test::noisy_sphere(2000, 0.1, 0.0, 3);
  write_point_cloud(dir / "in.ply", sphere);
  const ProgramRun r =
      run({"mesh", (dir / "in.ply").string(), "-o", (dir / "m.ply").string()}, dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const TriangleMesh m = read_triangle_mesh(dir / "m.ply");
  ASSERT_EQ(m.vertices.size(), sphere.size());
  EXPECT_LT((m.vertices[10] - sphere.positions[10]).norm(), 1e-7);
  EXPECT_EQ(m.triangles.size(), 2 * sphere.size() - 4);
  for (const char* key : {"method:", "afront", "faces:", "boundary loops:", "components:",
                          "non-manifold edges:", "2 (closed)", "time:"})
    EXPECT_TRUE(contains(r.out, key)) << key << "\n" << r.out;
}

TEST(MeshCliTest, PoissonNeedsNormalsAndSaysHowToGetThem) {
  const auto dir = test::make_temp_dir("mesh_cli");
  PointCloud sphere = test::noisy_sphere(2000, 0.1, 0.0, 4);
  sphere.normals.clear();
  write_point_cloud(dir / "bare.ply", sphere);
  const ProgramRun r = run(
      {"mesh", (dir / "bare.ply").string(), "-o", (dir / "m.ply").string(), "--method", "poisson"},
      dir);
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_TRUE(contains(r.err, "normals")) << r.err;
  EXPECT_FALSE(fs::exists(dir / "m.ply"));
  // With estimated normals it works and is watertight.
  const ProgramRun ok = run({"mesh", (dir / "bare.ply").string(), "-o", (dir / "m.ply").string(),
                             "--method", "poisson", "--estimate-normals"},
                            dir);
  ASSERT_EQ(ok.exit_code, 0) << ok.err;
  EXPECT_TRUE(contains(ok.out, "0 (0 edges)")) << ok.out;  // no boundary loop
  EXPECT_TRUE(contains(ok.out, "2 (closed)")) << ok.out;
}

TEST(MeshCliTest, BadOutputsAndOptionsExitBeforeReading) {
  const auto dir = test::make_temp_dir("mesh_cli");
  // The input does not exist: the bad option must be reported, not the missing file.
  const auto missing = (dir / "nothing.ply").string();
  EXPECT_EQ(run({"mesh", missing, "-o", (dir / "m.obj").string()}, dir).exit_code, 2);
  EXPECT_EQ(run({"mesh", missing, "-o", (dir / "m.ply").string(), "--method", "x"}, dir).exit_code,
            2);
  EXPECT_EQ(run({"mesh", missing, "-o", (dir / "m.ply").string(), "--beta", "3"}, dir).exit_code,
            2);
  EXPECT_EQ(run({"mesh", missing, "-o", (dir / "no" / "m.ply").string()}, dir).exit_code, 4);
  EXPECT_EQ(run({"mesh", missing, "-o", (dir / "m.ply").string()}, dir).exit_code, 4);
  PointCloud few = test::noisy_sphere(5, 1.0, 0.0, 1);
  write_point_cloud(dir / "few.ply", few);
  const ProgramRun r =
      run({"mesh", (dir / "few.ply").string(), "-o", (dir / "m.ply").string()}, dir);
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_TRUE(contains(r.err, "at least")) << r.err;
  EXPECT_FALSE(fs::exists(dir / "m.ply"));
}

TEST(MeshCliTest, FilterWithMeshCleansAndMeshesInOneCommand) {
  const auto dir = test::make_temp_dir("mesh_cli");
  PointCloud sphere = test::noisy_sphere(6000, 0.1, 0.001, 8);
  sphere.normals.clear();
  write_point_cloud(dir / "in.ply", sphere);
  // A bad --mesh path fails before the filter runs.
  const ProgramRun bad = run({"filter", (dir / "in.ply").string(), "-o", (dir / "out.ply").string(),
                              "--mesh", (dir / "m.stl").string()},
                             dir);
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_FALSE(fs::exists(dir / "out.ply"));
  const ProgramRun r = run({"filter", (dir / "in.ply").string(), "-o", (dir / "out.ply").string(),
                            "--mesh", (dir / "m.ply").string()},
                           dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const PointCloud cleaned = read_point_cloud(dir / "out.ply");
  const TriangleMesh m = read_triangle_mesh(dir / "m.ply");
  ASSERT_GT(cleaned.size(), 5000u);
  // The interpolating default: the cleaned points are the mesh's vertices, and they close the
  // sphere (Euler characteristic 2).
  ASSERT_EQ(m.vertices.size(), cleaned.size());
  for (std::size_t i = 0; i < cleaned.size(); i += 97)
    EXPECT_LT((m.vertices[i] - cleaned.positions[i]).norm(), 1e-7);
  EXPECT_TRUE(contains(r.out, "2 (closed)")) << r.out;
  double sum = 0;
  for (const auto& v : m.vertices) sum += std::abs(v.norm() - 0.1);
  EXPECT_LT(sum / static_cast<double>(m.vertices.size()), 0.0005);  // noise was 0.001
  EXPECT_TRUE(contains(r.out, "mesh faces:")) << r.out;
  EXPECT_TRUE(contains(r.out, "mesh file:")) << r.out;
}

}  // namespace
}  // namespace scanclean

#endif  // SCANCLEAN_PROGRAM

// The tiled (out-of-core) filter end to end: `scanclean filter --tiled` on a small cloud cut into
// several tiles, and `mpirun -np 2` / `-np 4 --oversubscribe` scanclean-mpi writing the same
// bytes as the single process.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <set>
#include <string>
#include <vector>

#include "scanclean/io/ply.h"
#include "support/program_run.h"
#include "support/synthetic.h"

namespace scanclean {
namespace {

namespace fs = std::filesystem;

class TiledProgram : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("scanclean_tiled_cli_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
    // A 10 m x 10 m noisy floor with clutter: a 64 MiB budget cuts it into several tiles.
    PointCloud c = test::noisy_plane(70000, 10.0, 0.01, 21);
    test::add_uniform_outliers(c, 700, -5.0, 5.0, 22);
    c.normals.clear();
    write_ply(dir_ / "in.ply", c);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST_F(TiledProgram, FilterTiledWritesEveryPointOnceAcrossTiles) {
  const auto r = test::run_program(
      SCANCLEAN_PROGRAM,
      {"filter", (dir_ / "in.ply").string(), "-o", (dir_ / "out.ply").string(), "--outliers",
       (dir_ / "removed.ply").string(), "--tiled", "--memory-budget", "64M"},
      dir_, 300);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("tiled, out of core"), std::string::npos) << r.out;
  // The provenance comment of the in-memory outputs: h, noise sigma and the command line.
  const std::string header = test::slurp(dir_ / "out.ply").substr(0, 2048);
  EXPECT_NE(header.find("\ncomment h="), std::string::npos) << header;
  EXPECT_NE(header.find("noise_sigma="), std::string::npos) << header;
  EXPECT_NE(header.find("command: scanclean filter"), std::string::npos) << header;
  const PointCloud out = read_ply(dir_ / "out.ply");
  const PointCloud removed = read_ply(dir_ / "removed.ply");
  ASSERT_GT(out.size(), 50000u);
  // No input point is both an output seed and removed, and none twice; the merge counts and
  // the removed points account for the input (up to clusters across tile borders).
  std::set<std::uint32_t> seen;
  double members = 0;
  for (double v : out.find_attribute("source_index")->values)
    EXPECT_TRUE(seen.insert(static_cast<std::uint32_t>(v)).second);
  for (double v : removed.find_attribute("source_index")->values)
    EXPECT_TRUE(seen.insert(static_cast<std::uint32_t>(v)).second);
  for (double v : out.find_attribute("merge_count")->values) members += v;
  const double accounted = members + static_cast<double>(removed.size());
  EXPECT_NEAR(accounted, 70700.0, 0.002 * 70700.0);
  // The scratch folder beside the output is gone.
  for (const auto& e : fs::directory_iterator(dir_))
    EXPECT_EQ(e.path().filename().string().rfind(".scanclean-tiles", 0), std::string::npos);
  // A text output cannot be streamed: refused before any work, exit 2.
  const auto bad = test::run_program(
      SCANCLEAN_PROGRAM,
      {"filter", (dir_ / "in.ply").string(), "-o", (dir_ / "out.xyz").string(), "--tiled"}, dir_,
      60);
  EXPECT_EQ(bad.exit_code, 2) << bad.err;
  EXPECT_NE(bad.err.find("binary PLY only"), std::string::npos) << bad.err;
}

#if defined(SCANCLEAN_MPI_PROGRAM) && defined(SCANCLEAN_MPIRUN)
// The PLY bytes without the provenance comment line ("comment h=... command: ..."), which names
// each run's own command line; fails the test when that line is missing.
std::string without_provenance(const std::string& ply) {
  const std::size_t at = ply.find("\ncomment h=");
  EXPECT_NE(at, std::string::npos) << "no provenance comment with h";
  if (at == std::string::npos) return ply;
  const std::size_t end = ply.find('\n', at + 1);
  EXPECT_NE(ply.find("command: ", at), std::string::npos);
  EXPECT_LT(ply.find("command: ", at), end);
  return ply.substr(0, at) + ply.substr(end);
}

TEST_F(TiledProgram, MpiRanksWriteTheSameBytesAsOneProcess) {
  if (!fs::exists(SCANCLEAN_MPIRUN)) GTEST_SKIP() << "mpirun not found: " << SCANCLEAN_MPIRUN;
  // CI runs as root, which OpenMPI refuses unless told.
  ::setenv("OMPI_ALLOW_RUN_AS_ROOT", "1", 1);
  ::setenv("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1", 1);
  const auto one = test::run_program(
      SCANCLEAN_PROGRAM,
      {"filter", (dir_ / "in.ply").string(), "-o", (dir_ / "one.ply").string(), "--outliers",
       (dir_ / "one_removed.ply").string(), "--tiled", "--memory-budget", "64M"},
      dir_, 300);
  ASSERT_EQ(one.exit_code, 0) << one.err;
  const std::string expected = without_provenance(test::slurp(dir_ / "one.ply"));
  const std::string expected_removed = without_provenance(test::slurp(dir_ / "one_removed.ply"));
  ASSERT_FALSE(expected.empty());
  for (const std::vector<std::string>& np :
       {std::vector<std::string>{"-np", "2"},
        std::vector<std::string>{"-np", "4", "--oversubscribe"}}) {
    std::vector<std::string> args = np;
    // Shared memory without the kernel's cross-process copy (refused in containers).
    for (const char* a : {"--mca", "btl_vader_single_copy_mechanism", "none"}) args.push_back(a);
    const std::string out = (dir_ / ("mpi" + np[1] + ".ply")).string();
    const std::string removed = (dir_ / ("mpi" + np[1] + "_removed.ply")).string();
    for (const std::string& a :
         {std::string(SCANCLEAN_MPI_PROGRAM), (dir_ / "in.ply").string(), std::string("-o"), out,
          std::string("--outliers"), removed, std::string("--memory-budget"), std::string("64M")})
      args.push_back(a);
    const auto r = test::run_program(SCANCLEAN_MPIRUN, args, dir_, 300);
    ASSERT_EQ(r.exit_code, 0) << "mpirun " << np[1] << " processes:\n" << r.out << r.err;
    EXPECT_NE(r.out.find("processes:"), std::string::npos) << r.out;
    EXPECT_TRUE(without_provenance(test::slurp(out)) == expected)
        << np[1] << " processes: output differs";
    EXPECT_TRUE(without_provenance(test::slurp(removed)) == expected_removed)
        << np[1] << " processes: outliers differ";
  }
}

// A fixed h that leaves three quarters of a 10k unit sphere (spacing about 35 mm) without a
// kernel: written, with the warning that scanclean filter gives (process 0 prints it once).
TEST_F(TiledProgram, MpiWarnsWhenMostPointsAreUnsupported) {
  if (!fs::exists(SCANCLEAN_MPIRUN)) GTEST_SKIP() << "mpirun not found: " << SCANCLEAN_MPIRUN;
  ::setenv("OMPI_ALLOW_RUN_AS_ROOT", "1", 1);
  ::setenv("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1", 1);
  PointCloud sphere = test::noisy_sphere(10000, 1.0, 0.01, 6);  // seed 6
  sphere.normals.clear();
  write_ply(dir_ / "sphere.ply", sphere);
  const auto r = test::run_program(
      SCANCLEAN_MPIRUN,
      {"-np", "2", "--mca", "btl_vader_single_copy_mechanism", "none", SCANCLEAN_MPI_PROGRAM,
       (dir_ / "sphere.ply").string(), "-o", (dir_ / "sphere_out.ply").string(), "--h", "0.05"},
      dir_, 300);
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_TRUE(fs::exists(dir_ / "sphere_out.ply"));
  const std::string all = r.out + r.err;
  const std::size_t at = all.find("of 10,000 points");
  ASSERT_NE(at, std::string::npos) << all;
  EXPECT_EQ(all.find("of 10,000 points", at + 1), std::string::npos) << "warned twice:\n" << all;
  EXPECT_NE(all.find("h = 50 mm"), std::string::npos) << all;
}
#else
TEST_F(TiledProgram, MpiRanksWriteTheSameBytesAsOneProcess) {
  GTEST_SKIP() << "scanclean-mpi not built (configure with -DSCANCLEAN_WITH_MPI=ON and install "
                  "openmpi-bin libopenmpi-dev)";
}
#endif

}  // namespace
}  // namespace scanclean

// The tiled (out-of-core) filter end to end: `scanclean filter --tiled` on a small cloud cut into
// several tiles, and `mpirun -np 2` / `-np 4 --oversubscribe` scanclean-mpi writing the same
// bytes as the single process.
#include <gtest/gtest.h>
#include <unistd.h>

#include <array>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
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

// Whether dir holds an output's temporary file (core/atomic_file.h: ".<name>.tmp.<pid>.<n>").
bool temporary_left(const fs::path& dir) {
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().filename().string().find(".tmp.") != std::string::npos) return true;
  return false;
}

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
  // The scratch folder beside the output is gone, and so are the outputs' temporary files.
  for (const auto& e : fs::directory_iterator(dir_))
    EXPECT_EQ(e.path().filename().string().rfind(".scanclean-tiles", 0), std::string::npos);
  EXPECT_FALSE(temporary_left(dir_));
  // A text output cannot be streamed: refused before any work, exit 2.
  const auto bad = test::run_program(
      SCANCLEAN_PROGRAM,
      {"filter", (dir_ / "in.ply").string(), "-o", (dir_ / "out.xyz").string(), "--tiled"}, dir_,
      60);
  EXPECT_EQ(bad.exit_code, 2) << bad.err;
  EXPECT_NE(bad.err.find("binary PLY only"), std::string::npos) << bad.err;
}

// A binary little-endian PLY of x y z confidence (float), written byte by byte: the library's
// writers keep NaN positions out, and these tests need them in the file.
void write_raw_ply(const fs::path& path, const std::vector<std::array<float, 4>>& records) {
  std::ofstream os(path, std::ios::binary);
  os << "ply\nformat binary_little_endian 1.0\nelement vertex " << records.size()
     << "\nproperty float x\nproperty float y\nproperty float z\nproperty float confidence\n"
        "end_header\n";
  for (const auto& r : records) os.write(reinterpret_cast<const char*>(r.data()), sizeof r);
}

// The floor of the fixture's size as raw records (confidence 0.9), every 500th with a NaN z.
std::vector<std::array<float, 4>> floor_with_nans(std::size_t n, std::size_t* nans) {
  const PointCloud c = test::noisy_plane(n, 10.0, 0.01, 23);
  std::vector<std::array<float, 4>> rec(c.size());
  *nans = 0;
  for (std::size_t i = 0; i < c.size(); ++i) {
    const bool nan = i % 500 == 7;
    *nans += nan;
    rec[i] = {
        static_cast<float>(c.positions[i].x()), static_cast<float>(c.positions[i].y()),
        nan ? std::numeric_limits<float>::quiet_NaN() : static_cast<float>(c.positions[i].z()),
        0.9f};
  }
  return rec;
}

// The value of a summary row ("  points in:     29,940"), or "" when there is no such row.
std::string summary_value(const std::string& out, const std::string& label) {
  const std::size_t at = out.find("  " + label);
  if (at == std::string::npos) return "";
  std::size_t b = at + 2 + label.size();
  while (b < out.size() && out[b] == ' ') ++b;
  return out.substr(b, out.find('\n', b) - b);
}

bool scratch_left(const fs::path& dir) {
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().filename().string().rfind(".scanclean-tiles", 0) == 0) return true;
  return false;
}

// Records with a NaN coordinate are dropped by the stream as by the whole-file readers, and
// counted: in the summary and in a warning, as the in-memory run counts them. A file of NaN
// records only is an input error (exit 3), as in memory, not an empty result.
TEST_F(TiledProgram, FilterTiledCountsTheRecordsItDrops) {
  std::size_t nans = 0;
  write_raw_ply(dir_ / "nan.ply", floor_with_nans(30000, &nans));
  ASSERT_EQ(nans, 60u);
  const auto r = test::run_program(
      SCANCLEAN_PROGRAM,
      {"filter", (dir_ / "nan.ply").string(), "-o", (dir_ / "nan_out.ply").string(), "--tiled"},
      dir_, 300);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(summary_value(r.out, "invalid dropped:"), "60") << r.out;
  EXPECT_EQ(summary_value(r.out, "points in:"), "29,940") << r.out;
  EXPECT_NE(r.err.find("nan.ply: 60 invalid points dropped while reading"), std::string::npos)
      << r.err;
  // In memory the same file gives the same count.
  const auto m = test::run_program(SCANCLEAN_PROGRAM,
                                   {"filter", (dir_ / "nan.ply").string(), "-o",
                                    (dir_ / "nan_mem.ply").string(), "--memory-budget", "off"},
                                   dir_, 300);
  ASSERT_EQ(m.exit_code, 0) << m.err;
  EXPECT_NE(m.err.find("nan.ply: 60 invalid points dropped while reading"), std::string::npos)
      << m.err;

  write_raw_ply(dir_ / "allnan.ply",
                std::vector<std::array<float, 4>>(
                    50, {std::numeric_limits<float>::quiet_NaN(), 0.0f, 0.0f, 1.0f}));
  const auto e = test::run_program(SCANCLEAN_PROGRAM,
                                   {"filter", (dir_ / "allnan.ply").string(), "-o",
                                    (dir_ / "allnan_out.ply").string(), "--tiled"},
                                   dir_, 60);
  EXPECT_EQ(e.exit_code, 3) << e.out << e.err;
  EXPECT_NE(e.err.find("allnan.ply: all 50 records: no point with a finite x, y and z"),
            std::string::npos)
      << e.err;
  EXPECT_FALSE(fs::exists(dir_ / "allnan_out.ply"));
  EXPECT_FALSE(scratch_left(dir_));
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

// mpirun `np` (e.g. {"-np", "2"}) scanclean-mpi `args`, in dir. CI runs as root, which OpenMPI
// refuses unless told; shared memory goes without the kernel's cross-process copy (refused in
// containers).
test::ProgramRun run_mpi(const std::vector<std::string>& np, const std::vector<std::string>& args,
                         const fs::path& dir) {
  ::setenv("OMPI_ALLOW_RUN_AS_ROOT", "1", 1);
  ::setenv("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1", 1);
  std::vector<std::string> all = np;
  for (const char* a : {"--mca", "btl_vader_single_copy_mechanism", "none", SCANCLEAN_MPI_PROGRAM})
    all.push_back(a);
  all.insert(all.end(), args.begin(), args.end());
  return test::run_program(SCANCLEAN_MPIRUN, all, dir, 300);
}

TEST_F(TiledProgram, MpiRanksWriteTheSameBytesAsOneProcess) {
  if (!fs::exists(SCANCLEAN_MPIRUN)) GTEST_SKIP() << "mpirun not found: " << SCANCLEAN_MPIRUN;
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
    const std::string out = (dir_ / ("mpi" + np[1] + ".ply")).string();
    const std::string removed = (dir_ / ("mpi" + np[1] + "_removed.ply")).string();
    const auto r = run_mpi(
        np,
        {(dir_ / "in.ply").string(), "-o", out, "--outliers", removed, "--memory-budget", "64M"},
        dir_);
    ASSERT_EQ(r.exit_code, 0) << "mpirun " << np[1] << " processes:\n" << r.out << r.err;
    EXPECT_NE(r.out.find("processes:"), std::string::npos) << r.out;
    EXPECT_TRUE(without_provenance(test::slurp(out)) == expected)
        << np[1] << " processes: output differs";
    EXPECT_TRUE(without_provenance(test::slurp(removed)) == expected_removed)
        << np[1] << " processes: outliers differ";
    // Every process wrote its tiles' results into the outputs in place; nothing is left over.
    EXPECT_FALSE(scratch_left(dir_)) << np[1] << " processes";
    EXPECT_FALSE(temporary_left(dir_)) << np[1] << " processes";
  }
}

// A fixed h that leaves three quarters of a 10k unit sphere (spacing about 35 mm) without a
// kernel: written, with the warning that scanclean filter gives (process 0 prints it once).
TEST_F(TiledProgram, MpiWarnsWhenMostPointsAreUnsupported) {
  if (!fs::exists(SCANCLEAN_MPIRUN)) GTEST_SKIP() << "mpirun not found: " << SCANCLEAN_MPIRUN;
  PointCloud sphere = test::noisy_sphere(10000, 1.0, 0.01, 6);  // seed 6
  sphere.normals.clear();
  write_ply(dir_ / "sphere.ply", sphere);
  const auto r = run_mpi(
      {"-np", "2"},
      {(dir_ / "sphere.ply").string(), "-o", (dir_ / "sphere_out.ply").string(), "--h", "0.05"},
      dir_);
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_TRUE(fs::exists(dir_ / "sphere_out.ply"));
  const std::string all = r.out + r.err;
  const std::size_t at = all.find("of 10,000 points");
  ASSERT_NE(at, std::string::npos) << all;
  EXPECT_EQ(all.find("of 10,000 points", at + 1), std::string::npos) << "warned twice:\n" << all;
  EXPECT_NE(all.find("h = 50 mm"), std::string::npos) << all;
}

// A record near the end of the file, in the last process's byte range, with a confidence of
// 1.5: that process stops the run, naming the record, and aborts the others (exit 3). Nothing
// is left behind: no output, no scratch folder (process 0, which owns it, is killed by the
// abort and cannot remove it; the process that failed does).
TEST_F(TiledProgram, MpiRunStoppedByOneProcessLeavesNoScratch) {
  if (!fs::exists(SCANCLEAN_MPIRUN)) GTEST_SKIP() << "mpirun not found: " << SCANCLEAN_MPIRUN;
  std::size_t nans = 0;
  auto rec = floor_with_nans(30000, &nans);
  rec[rec.size() - 5][3] = 1.5f;
  write_raw_ply(dir_ / "bad.ply", rec);
  const auto r = run_mpi({"-np", "2"},
                         {(dir_ / "bad.ply").string(), "-o", (dir_ / "bad_out.ply").string(),
                          "--memory-budget", "64M"},
                         dir_);
  EXPECT_EQ(r.exit_code, 3) << r.out << r.err;
  EXPECT_NE(r.err.find("(process 1): error: tiled filter input: record 29995: confidence 1.5"),
            std::string::npos)
      << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "bad_out.ply"));
  EXPECT_FALSE(scratch_left(dir_));
}
#else
TEST_F(TiledProgram, MpiRanksWriteTheSameBytesAsOneProcess) {
  GTEST_SKIP() << "scanclean-mpi not built (configure with -DSCANCLEAN_WITH_MPI=ON and install "
                  "openmpi-bin libopenmpi-dev)";
}
#endif

}  // namespace
}  // namespace scanclean

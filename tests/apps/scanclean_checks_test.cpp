// The program's checks before work and its answers to results that would be silently wrong
// (issue: no silent wrong result): every case runs the built program in a child process and
// checks the exit code, the message and the files left behind.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "scanclean/io/point_cloud_io.h"
#include "support/data_paths.h"
#include "support/program_run.h"
#include "support/synthetic.h"

namespace fs = std::filesystem;

namespace scanclean {
namespace {

using Outcome = test::ProgramRun;
using test::slurp;

//! The program with `args`, stdin from /dev/null; killed after `limit_s` seconds (exit 124).
Outcome run(const std::vector<std::string>& args, const fs::path& dir, int limit_s = 120) {
  return test::run_program(SCANCLEAN_PROGRAM, args, dir, limit_s);
}

bool has(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

//! A 0.3 m x 0.3 m board (z = 0, 1 mm noise, seeded) written as x y z [r g b] text.
fs::path write_board_xyz(const fs::path& file, bool colours) {
  const PointCloud c = test::noisy_plane(3000, 0.3, 0.001, 17);
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> byte(0, 255);
  std::ofstream out(file);
  for (const auto& p : c.positions) {
    out << p.x() << ' ' << p.y() << ' ' << p.z();
    if (colours) out << ' ' << byte(rng) << ' ' << byte(rng) << ' ' << byte(rng);
    out << '\n';
  }
  return file;
}

double rms_z(const PointCloud& cloud) {
  double sum = 0;
  for (const auto& p : cloud.positions) sum += p.z() * p.z();
  return cloud.empty() ? 0.0 : std::sqrt(sum / static_cast<double>(cloud.size()));
}

fs::path write_plane_ply(const fs::path& file, std::size_t n = 2000) {
  write_point_cloud(file, test::noisy_plane(n, 0.2, 0.0005, 3));
  return file;
}

TEST(ScancleanChecksTest, XyzColourColumnsAreReadAsColoursNotNormals) {
  const auto dir = test::make_temp_dir("checks");
  const fs::path plain = write_board_xyz(dir / "plain.xyz", false);
  const fs::path rgb = write_board_xyz(dir / "rgb.xyz", true);
  const Outcome a = run({"filter", plain.string(), "-o", (dir / "a.ply").string()}, dir);
  ASSERT_EQ(a.exit_code, 0) << a.err;
  const Outcome b = run({"filter", rgb.string(), "-o", (dir / "b.ply").string()}, dir);
  ASSERT_EQ(b.exit_code, 0) << b.err;
  const double rms_plain = rms_z(read_point_cloud(dir / "a.ply"));
  const double rms_rgb = rms_z(read_point_cloud(dir / "b.ply"));
  // Colours read as normals made the board 34x rougher; read as colours they change nothing.
  EXPECT_LT(rms_rgb, 1.2 * rms_plain) << "plain " << rms_plain << " m, with rgb " << rms_rgb;
  const PointCloud back = read_point_cloud(dir / "b.ply");
  EXPECT_FALSE(back.has_colors() && back.colors.empty());
  const Outcome info = run({"info", rgb.string()}, dir);
  EXPECT_EQ(info.exit_code, 0) << info.err;
  EXPECT_TRUE(has(info.out, "x y z r g b")) << info.out;
  EXPECT_TRUE(has(info.out, "colours")) << info.out;
  EXPECT_TRUE(has(info.out, "guessed")) << info.out;
  // Stated explicitly, the same columns are read as given.
  const Outcome given = run({"info", rgb.string(), "--xyz-columns", "x,y,z,r,g,b"}, dir);
  EXPECT_EQ(given.exit_code, 0) << given.err;
  EXPECT_TRUE(has(given.out, "as given")) << given.out;
  const Outcome bad = run({"info", rgb.string(), "--xyz-columns", "x,y,q"}, dir);
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_TRUE(has(bad.err, "--xyz-columns")) << bad.err;
}

TEST(ScancleanChecksTest, OutputEqualToAnInputOrAnotherOutputIsRefusedBeforeWork) {
  const auto dir = test::make_temp_dir("checks");
  const fs::path in = write_plane_ply(dir / "scan.ply");
  const std::string before = slurp(in);
  const Outcome same = run({"filter", in.string(), "-o", in.string()}, dir);
  EXPECT_EQ(same.exit_code, 2) << same.err;
  EXPECT_TRUE(has(same.err, "-o") && has(same.err, "input")) << same.err;
  EXPECT_EQ(slurp(in), before) << "the raw scan was overwritten";
  const fs::path out = dir / "clean.ply";
  const Outcome both =
      run({"filter", in.string(), "-o", out.string(), "--outliers", out.string()}, dir);
  EXPECT_EQ(both.exit_code, 2) << both.err;
  EXPECT_TRUE(has(both.err, "--outliers")) << both.err;
  EXPECT_FALSE(fs::exists(out));
  const Outcome conv = run({"convert", in.string(), in.string()}, dir);
  EXPECT_EQ(conv.exit_code, 2) << conv.err;
  EXPECT_EQ(slurp(in), before);
}

TEST(ScancleanChecksTest, CollapsedOrEmptyResultsExitSixAndWriteNothing) {
  const auto dir = test::make_temp_dir("checks");
  const fs::path in = write_plane_ply(dir / "scan.ply");
  for (const auto& extra : std::vector<std::vector<std::string>>{
           {"--h", "1e-9"}, {"--h", "1000"}, {"--merge-eps", "1"}}) {
    std::vector<std::string> args{"filter", in.string(), "-o", (dir / "out.ply").string()};
    args.insert(args.end(), extra.begin(), extra.end());
    const Outcome r = run(args, dir);
    EXPECT_EQ(r.exit_code, 6) << extra[0] << " " << extra[1] << ": " << r.err;
    EXPECT_TRUE(has(r.err, "collapsed") || has(r.err, "nothing usable")) << r.err;
    EXPECT_FALSE(fs::exists(dir / "out.ply")) << extra[0] << " " << extra[1];
  }
  // One point in, nothing out.
  const fs::path one = dir / "one.xyz";
  std::ofstream(one) << "0.1 0.2 0.3\n";
  const Outcome r = run({"filter", one.string(), "-o", (dir / "one_out.ply").string()}, dir);
  EXPECT_EQ(r.exit_code, 6) << r.err;
  EXPECT_FALSE(fs::exists(dir / "one_out.ply"));
}

TEST(ScancleanChecksTest, EmptyXyzIsAnErrorLikeEmptyPlyAndPcd) {
  const auto dir = test::make_temp_dir("checks");
  std::ofstream(dir / "empty.xyz") << "# nothing here\n\n";
  const Outcome r = run({"info", (dir / "empty.xyz").string()}, dir);
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_TRUE(has(r.err, "empty.xyz") && has(r.err, "no points")) << r.err;
}

TEST(ScancleanChecksTest, OutOfRangeOptionsAreRefusedNamingTheOptionAsTyped) {
  const auto dir = test::make_temp_dir("checks");
  const fs::path in = write_plane_ply(dir / "scan.ply");
  const std::string out = (dir / "out.ply").string();
  for (const auto& [option, value] :
       std::vector<std::pair<std::string, std::string>>{{"--merge-eps", "-1"},
                                                        {"--small-components", "-1"},
                                                        {"--k-h", "1"},
                                                        {"--tau", "2"},
                                                        {"--passes", "3"}}) {
    const Outcome r = run({"filter", in.string(), "-o", out, option, value}, dir);
    EXPECT_EQ(r.exit_code, 2) << option << " " << value << ": " << r.err;
    EXPECT_TRUE(has(r.err, option)) << r.err;
    EXPECT_FALSE(has(r.err, "k_h")) << r.err;
  }
  const Outcome replay = run({"replay", dir.string(), "-o", out, "--merge-eps", "-1"}, dir);
  EXPECT_EQ(replay.exit_code, 2) << replay.err;
  EXPECT_TRUE(has(replay.err, "--merge-eps")) << replay.err;
#if defined(SCANCLEAN_HAVE_SL)
  const Outcome sl = run({"sl", "decode", dir.string(), "-o", out, "--white-threshold", "-5"}, dir);
  EXPECT_EQ(sl.exit_code, 2) << sl.err;
  EXPECT_TRUE(has(sl.err, "--white-threshold")) << sl.err;
#endif
  EXPECT_FALSE(fs::exists(out));
}

#if defined(SCANCLEAN_HAVE_SL)
// The structured-light commands share the output checks: a calibration written over the
// reference it is compared with, or a cloud into a missing folder, is refused before any capture
// is read (the captures here do not even exist).
TEST(ScancleanChecksTest, StructuredLightOutputsAreCheckedBeforeWork) {
  const auto dir = test::make_temp_dir("checks");
  const fs::path reference = dir / "calib.yml";
  std::ofstream(reference) << "%YAML:1.0\n";
  const std::string before = test::slurp(reference);
  const Outcome same = run({"sl", "calibrate", (dir / "nowhere").string(), "-o", reference.string(),
                            "--compare", reference.string()},
                           dir);
  EXPECT_EQ(same.exit_code, 2) << same.err;
  EXPECT_TRUE(has(same.err, "-o") && has(same.err, "--compare") && has(same.err, "same file"))
      << same.err;
  EXPECT_EQ(test::slurp(reference), before);
  const Outcome missing =
      run({"sl", "decode", (dir / "nowhere").string(), "-o", (dir / "no_dir" / "out.ply").string()},
          dir);
  EXPECT_EQ(missing.exit_code, 4) << missing.err;
  EXPECT_TRUE(has(missing.err, "no_dir") && has(missing.err, "does not exist")) << missing.err;
}
#endif

TEST(ScancleanChecksTest, IntrinsicsForASourceThatCarriesItsOwnAreRefused) {
  const auto dir = test::make_temp_dir("checks");
  const fs::path oni = test::recordings_dir() / "oni" / "3dj_test.oni";
  const Outcome r = run({"replay", oni.string(), "-o", (dir / "o.ply").string(), "--fx", "500",
                         "--fy", "500", "--cx", "320", "--cy", "240"},
                        dir);
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_TRUE(has(r.err, "depth images only")) << r.err;
  EXPECT_FALSE(fs::exists(dir / "o.ply"));
  // capture's message about missing intrinsics names --fx --fy --cx --cy: capture has them.
  const Outcome help = run({"capture", "--help"}, dir);
  EXPECT_EQ(help.exit_code, 0);
  EXPECT_TRUE(has(help.out, "--fx") && has(help.out, "--cy")) << help.out;
}

TEST(ScancleanChecksTest, MissingOutputFolderIsReportedBeforeReadingAndNamed) {
  const auto dir = test::make_temp_dir("checks");
  // The input is malformed: if it were read first, the error would be about it (exit 3).
  const fs::path bad = dir / "bad.ply";
  std::ofstream(bad) << "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n";
  const fs::path out = dir / "no_such_folder" / "clean.ply";
  const Outcome r = run({"filter", bad.string(), "-o", out.string()}, dir);
  EXPECT_EQ(r.exit_code, 4) << r.err;
  EXPECT_TRUE(has(r.err, "no_such_folder\" does not exist")) << r.err;
  EXPECT_FALSE(has(r.err, ".tmp.")) << "names the temporary file: " << r.err;
}

TEST(ScancleanChecksTest, AFolderGivenAsInputIsReportedAsAFolder) {
  const auto dir = test::make_temp_dir("checks");
  fs::create_directories(dir / "scans");
  const Outcome f = run({"filter", (dir / "scans").string(), "-o", (dir / "o.ply").string()}, dir);
  EXPECT_EQ(f.exit_code, 3) << f.err;
  EXPECT_TRUE(has(f.err, "is a folder")) << f.err;
  const Outcome i = run({"info", (dir / "scans").string()}, dir);
  EXPECT_EQ(i.exit_code, 3) << i.err;
  EXPECT_TRUE(has(i.err, "is a folder")) << i.err;
  EXPECT_FALSE(has(i.err, "unsupported file extension")) << i.err;
}

TEST(ScancleanChecksTest, FilterTakesAPositionalOutputAsTheReadmeSays) {
  const auto dir = test::make_temp_dir("checks");
  const fs::path in = write_plane_ply(dir / "scan.ply");
  const std::string before = slurp(in);
  const Outcome r = run({"filter", in.string(), (dir / "clean.ply").string()}, dir);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(dir / "clean.ply"));
  EXPECT_TRUE(has(r.out, "1 file")) << "the output was read as an input:\n" << r.out;
  EXPECT_EQ(slurp(in), before);
}

TEST(ScancleanChecksTest, InfoOnManyCoincidentPointsFinishes) {
  const auto dir = test::make_temp_dir("checks");
  PointCloud c;
  c.positions.assign(1000000, Eigen::Vector3d(0.5, -0.25, 1.0));
  c.positions.push_back(Eigen::Vector3d(0.5, -0.25, 1.001));
  write_point_cloud(dir / "same.ply", c);
  const Outcome r = run({"info", (dir / "same.ply").string()}, dir, 60);
  ASSERT_EQ(r.exit_code, 0) << "exit " << r.exit_code << " (124 = still running after 60 s)\n"
                            << r.err;
  EXPECT_TRUE(has(r.out, "999,999 repeat an earlier position")) << r.out;
  EXPECT_TRUE(has(r.out, "1.000 mm")) << r.out;
}

TEST(ScancleanChecksTest, MalformedCorpusFilesExitThreeNamingTheFile) {
  const auto dir = test::make_temp_dir("checks");
  const fs::path corpus = fs::path(SCANCLEAN_SOURCE_DIR) / "tests" / "data" / "malformed";
  for (const char* name : {"ply_count_huge.ply", "pcd_compressed_size_lie.pcd",
                           "xyz_six_ambiguous.xyz", "xyz_empty.xyz", "ply_list_count_lies.ply"}) {
    const Outcome info = run({"info", (corpus / name).string()}, dir);
    EXPECT_EQ(info.exit_code, 3) << name << ": " << info.err;
    EXPECT_TRUE(has(info.err, name)) << info.err;
    const Outcome filter =
        run({"filter", (corpus / name).string(), "-o", (dir / "o.ply").string()}, dir);
    EXPECT_EQ(filter.exit_code, 3) << name << ": " << filter.err;
    EXPECT_FALSE(fs::exists(dir / "o.ply"));
  }
}

#if defined(SCANCLEAN_HAVE_OPENNI2)
//! A 3-frame recording folder made from the bundled .oni, for the cases below.
fs::path small_recording(const fs::path& dir) {
  const fs::path rec = dir / "rec";
  const Outcome r =
      run({"record", "--source", (test::recordings_dir() / "oni" / "3dj_test.oni").string(),
           rec.string(), "--frames", "3"},
          dir);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  return rec;
}

void replace_in_file(const fs::path& file, const std::string& from, const std::string& to) {
  std::string text = slurp(file);
  const auto at = text.find(from);
  ASSERT_NE(at, std::string::npos) << from << " not in " << file;
  text.replace(at, from.size(), to);
  std::ofstream(file, std::ios::binary | std::ios::trunc) << text;
}

TEST(ScancleanChecksTest, RecordFromAFiniteVirtualSensorFolderNeedsNoFrameCount) {
  const auto dir = test::make_temp_dir("checks");
  const fs::path rec = small_recording(dir);
  const Outcome r = run({"record", "--source", "vsensor://" + fs::absolute(rec).string(),
                         (dir / "copy.oni").string()},
                        dir);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(dir / "copy.oni"));
  // A looping folder is endless: the frame count is still required.
  const Outcome loop =
      run({"record", "--source", "vsensor://" + fs::absolute(rec).string() + "?loop=1",
           (dir / "loop.oni").string()},
          dir);
  EXPECT_EQ(loop.exit_code, 2) << loop.err;
}

TEST(ScancleanChecksTest, AHugeNumberInSessionJsonIsAnInputErrorNamingFileAndKey) {
  const auto dir = test::make_temp_dir("checks");
  const fs::path rec = small_recording(dir);
  replace_in_file(rec / "session.json", "\"fx\": ", "\"fx\": 1e400, \"was_fx\": ");
  const Outcome r = run({"replay", rec.string(), "-o", (dir / "o.ply").string()}, dir);
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_TRUE(has(r.err, "session.json")) << r.err;
  EXPECT_TRUE(has(r.err, "key \"fx\"")) << r.err;
}

TEST(ScancleanChecksTest, AReplayWindowLeftMostlyUnsupportedIsWarnedAbout) {
  // h = 2 mm on the 3dj recording's depth frames (points about 2-6 mm apart) leaves almost every
  // point without a kernel: a few hundred points are written (exit 0), with a warning that
  // names the window, the share and h, and a summary row. The automatic h gives no warning.
  const auto dir = test::make_temp_dir("checks");
  const fs::path rec = small_recording(dir);
  const Outcome r =
      run({"replay", rec.string(), "-o", (dir / "o.ply").string(), "--h", "0.002"}, dir);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(dir / "o.ply"));
  EXPECT_TRUE(has(r.err, "window 0") && has(r.err, "warning") && has(r.err, "h = 2 mm") &&
              has(r.err, "unsupported"))
      << r.err;
  const auto row = r.out.find("windows mostly unsupported (written):");
  ASSERT_NE(row, std::string::npos) << r.out;
  const std::string line = r.out.substr(row, r.out.find('\n', row) - row);
  EXPECT_EQ(line.substr(line.find_last_of(' ') + 1), "1") << line;  // one window
  const Outcome automatic = run({"replay", rec.string(), "-o", (dir / "a.ply").string()}, dir);
  EXPECT_EQ(automatic.exit_code, 0) << automatic.err;
  EXPECT_FALSE(has(automatic.err, "warning")) << automatic.err;
  EXPECT_FALSE(has(automatic.out, "mostly unsupported")) << automatic.out;
}

TEST(ScancleanChecksTest, RecordingRecoveryWarningsArePrinted) {
  const auto dir = test::make_temp_dir("checks");
  const fs::path rec = small_recording(dir);
  // As if the writer was killed: not finalized, a partial last line in frames.csv.
  replace_in_file(rec / "session.json", "\"finalized\": true", "\"finalized\": false");
  replace_in_file(rec / "session.json", "\"frame_count\": 3,", "");
  std::ofstream(rec / "frames.csv", std::ios::app) << "4,1234";
  const Outcome r = run({"replay", rec.string(), "-o", (dir / "o.ply").string(), "--raw"}, dir);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(has(r.err, "warning") && has(r.err, "frames.csv")) << r.err;
  EXPECT_TRUE(has(r.out, "source warnings")) << r.out;
}
#endif

}  // namespace
}  // namespace scanclean

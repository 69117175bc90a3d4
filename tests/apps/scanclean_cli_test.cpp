// The scanclean program end to end, as a script drives it: every run is a child process, its exit
// code is checked against the documented table (0 ok, 2 bad option, 3 bad input data, 4 file I/O
// failure, 5 device unavailable) and its output files are read back.

#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "scanclean/io/point_cloud_io.h"
#include "support/data_paths.h"
#include "support/program_run.h"
#include "support/synthetic.h"

namespace fs = std::filesystem;

namespace scanclean {
namespace {

using test::ProgramRun;
using test::slurp;

//! Runs the program with `args` (no shell expansion of the arguments), stdin from /dev/null.
ProgramRun run(const std::vector<std::string>& args, const fs::path& dir) {
  return test::run_program(SCANCLEAN_PROGRAM, args, dir);
}

//! Runs `scanclean filter DIR/in.ply -o DIR/out.ply EXTRA...`.
ProgramRun run_filter_in(const fs::path& dir, const std::vector<std::string>& extra) {
  std::vector<std::string> args = {"filter", (dir / "in.ply").string(), "-o",
                                   (dir / "out.ply").string()};
  args.insert(args.end(), extra.begin(), extra.end());
  return run(args, dir);
}

bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

double rms_z(const PointCloud& cloud) {
  double sum = 0;
  for (const auto& p : cloud.positions) sum += p.z() * p.z();
  return cloud.empty() ? 0.0 : std::sqrt(sum / static_cast<double>(cloud.size()));
}

TEST(ScancleanCliTest, HelpListsTheSubcommandsAndExitCodes) {
  const auto dir = test::make_temp_dir("cli");
  const ProgramRun r = run({"--help"}, dir);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  for (const char* word :
       {"info", "convert", "filter", "replay", "capture", "record", "devices", "sl", "Exit codes"})
    EXPECT_TRUE(contains(r.out, word)) << "--help does not mention " << word << ":\n" << r.out;
  const ProgramRun sub = run({"filter", "--help"}, dir);
  EXPECT_EQ(sub.exit_code, 0);
  EXPECT_TRUE(contains(sub.out, "--merge-eps")) << sub.out;
}

TEST(ScancleanCliTest, BadCommandLinesExitTwoWithTheReason) {
  const auto dir = test::make_temp_dir("cli");
  const ProgramRun none = run({}, dir);
  EXPECT_EQ(none.exit_code, 2);
  const ProgramRun unknown = run({"frobnicate"}, dir);
  EXPECT_EQ(unknown.exit_code, 2);
  const ProgramRun no_output = run({"filter", "in.ply"}, dir);
  EXPECT_EQ(no_output.exit_code, 2);
  EXPECT_TRUE(contains(no_output.err, "--output")) << no_output.err;
  const ProgramRun negative =
      run({"filter", "in.ply", "-o", (dir / "o.ply").string(), "--h", "-1"}, dir);
  EXPECT_EQ(negative.exit_code, 2);
  EXPECT_TRUE(contains(negative.err, "expected a number > 0, got -1")) << negative.err;
  EXPECT_FALSE(fs::exists(dir / "o.ply"));
}

TEST(ScancleanCliTest, MissingFileExitsFourNamingIt) {
  const auto dir = test::make_temp_dir("cli");
  const fs::path missing = dir / "no_such_scan.ply";
  const ProgramRun r = run({"info", missing.string()}, dir);
  EXPECT_EQ(r.exit_code, 4) << r.err;
  EXPECT_TRUE(contains(r.err, missing.string())) << r.err;
}

TEST(ScancleanCliTest, MalformedFileExitsThreeNamingFileAndPlace) {
  const auto dir = test::make_temp_dir("cli");
  const fs::path bad = dir / "truncated.ply";
  std::ofstream(bad) << "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                        "property float y\nproperty float z\nend_header\n1 2 3\n4 5\n";
  const ProgramRun r = run({"info", bad.string()}, dir);
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_TRUE(contains(r.err, bad.string())) << r.err;
  EXPECT_TRUE(contains(r.err, "line")) << r.err;
  // The same file as filter input: the same exit code, and no output appears.
  const ProgramRun f = run({"filter", bad.string(), "-o", (dir / "out.ply").string()}, dir);
  EXPECT_EQ(f.exit_code, 3) << f.err;
  EXPECT_FALSE(fs::exists(dir / "out.ply"));
}

TEST(ScancleanCliTest, ConvertRoundTripKeepsEveryPointAndNormal) {
  const auto dir = test::make_temp_dir("cli");
  const PointCloud cloud = test::noisy_sphere(500, 0.2, 0.001, 11);
  write_point_cloud(dir / "in.ply", cloud);
  ASSERT_EQ(run({"convert", (dir / "in.ply").string(), (dir / "mid.pcd").string()}, dir).exit_code,
            0);
  const ProgramRun back =
      run({"convert", (dir / "mid.pcd").string(), (dir / "back.xyz").string()}, dir);
  ASSERT_EQ(back.exit_code, 0) << back.err;
  const PointCloud read = read_point_cloud(dir / "back.xyz");
  ASSERT_EQ(read.size(), cloud.size());
  ASSERT_TRUE(read.has_normals());
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    EXPECT_LT((read.positions[i] - cloud.positions[i]).norm(), 1e-6) << i;
    EXPECT_LT((read.normals[i] - cloud.normals[i]).norm(), 1e-5) << i;
  }
}

#ifdef SCANCLEAN_HAVE_FILTER
TEST(ScancleanCliTest, FilterSmoothsAPlaneAndAccountsForEveryPoint) {
  const auto dir = test::make_temp_dir("cli");
  PointCloud cloud = test::noisy_plane(4000, 1.0, 0.004, 21);
  cloud.normals.clear();
  const auto outliers = test::add_uniform_outliers(cloud, 40, -0.5, 0.5, 22);
  (void)outliers;
  write_point_cloud(dir / "in.ply", cloud);
  const fs::path out = dir / "clean.ply", removed = dir / "removed.ply";
  const ProgramRun r = run({"filter", (dir / "in.ply").string(), "-o", out.string(), "--merge-eps",
                            "0", "--outliers", removed.string(), "--threads", "2"},
                           dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(contains(r.out, "points in")) << r.out;
  const PointCloud clean = read_point_cloud(out);
  const PointCloud dropped = read_point_cloud(removed);
  // Nothing lost silently: without merging, kept + removed = input.
  EXPECT_EQ(clean.size() + dropped.size(), cloud.size());
  EXPECT_GE(dropped.size(), 30u);  // most of the 40 box outliers (some land on the plane)
  EXPECT_LE(dropped.size(), 80u);
  // The kept plane points lie much closer to z = 0 than the input's noise (sigma 0.004).
  const auto* source = clean.find_attribute("source_index");
  ASSERT_NE(source, nullptr);
  std::vector<std::size_t> plane_points;
  for (std::size_t i = 0; i < clean.size(); ++i)
    if (source->values[i] < 4000) plane_points.push_back(i);
  EXPECT_GT(plane_points.size(), 3960u);
  const double rms = rms_z(select(clean, plane_points));
  EXPECT_LT(rms, 0.004 / 3) << "filtered RMS " << rms;
  // No stray temporary files beside the outputs.
  for (const auto& entry : fs::directory_iterator(dir))
    EXPECT_FALSE(contains(entry.path().filename().string(), ".tmp")) << entry.path();
}

TEST(ScancleanCliTest, OutlierSigmaOptionReachesTheFilter) {
  // Outliers 0.03-0.07 off a plane (h is about 0.09 here): the off-surface test drops them by
  // default, and --outlier-sigma 0 turns it off (the summary counts them "off surface"). At the
  // noise rule's h (--scale-gamma 0): the scale test would raise h on this plane and thin the
  // kernels, and most outliers, left without a kernel of their own, would fall as unsupported.
  const auto dir = test::make_temp_dir("cli");
  PointCloud cloud = test::noisy_plane(4000, 1.0, 0.004, 23);
  cloud.normals.clear();
  std::mt19937 rng(24);  // seed 24
  std::uniform_real_distribution<double> u(-0.45, 0.45), off(0.03, 0.07);
  for (int k = 0; k < 40; ++k) {
    const double z = (k % 2 ? 1 : -1) * off(rng), y = u(rng), x = u(rng);  // gcc's order
    cloud.positions.emplace_back(x, y, z);
  }
  write_point_cloud(dir / "in.ply", cloud);
  auto off_surface = [&](const std::vector<std::string>& extra) {
    std::vector<std::string> args = {
        "filter", (dir / "in.ply").string(), "-o", (dir / "out.ply").string(), "--scale-gamma",
        "0"};
    args.insert(args.end(), extra.begin(), extra.end());
    const ProgramRun r = run(args, dir);
    EXPECT_EQ(r.exit_code, 0) << r.err;
    const auto at = r.out.find("off surface ");
    EXPECT_NE(at, std::string::npos) << r.out;
    return at == std::string::npos ? -1L : std::stol(r.out.substr(at + 12));
  };
  EXPECT_GE(off_surface({}), 20L);
  EXPECT_EQ(off_surface({"--outlier-sigma", "0"}), 0L);
  EXPECT_EQ(run({"filter", (dir / "in.ply").string(), "-o", (dir / "o.ply").string(),
                 "--outlier-sigma", "-1"},
                dir)
                .exit_code,
            2);
}

TEST(ScancleanCliTest, ScaleGammaOptionReachesTheFilter) {
  // On a plane the scale test raises h above the noise rule's (the summary shows both);
  // --scale-gamma 0 keeps the noise rule's h, and a negative value exits 2.
  const auto dir = test::make_temp_dir("cli");
  PointCloud cloud = test::noisy_plane(4000, 1.0, 0.004, 25);  // seed 25
  cloud.normals.clear();
  write_point_cloud(dir / "in.ply", cloud);
  auto run_filter = [&](const std::vector<std::string>& extra) {
    return run_filter_in(dir, extra);
  };
  // The value (mm) of a summary line "  key:   value mm".
  auto mm_after = [](const std::string& out, const std::string& key) {
    const std::string line = "\n  " + key + ":";
    const auto at = out.find(line);
    return at == std::string::npos ? -1.0 : std::stod(out.substr(at + line.size()));
  };
  const ProgramRun on = run_filter({});
  ASSERT_EQ(on.exit_code, 0) << on.err;
  const double h = mm_after(on.out, "h"), before = mm_after(on.out, "h before the scale test");
  ASSERT_GT(before, 0) << on.out;
  EXPECT_GT(h, 1.3 * before) << on.out;
  const ProgramRun off = run_filter({"--scale-gamma", "0"});
  ASSERT_EQ(off.exit_code, 0) << off.err;
  EXPECT_EQ(off.out.find("h before the scale test"), std::string::npos) << off.out;
  EXPECT_NEAR(mm_after(off.out, "h"), before, 1e-3 * before) << off.out;
  EXPECT_EQ(run_filter({"--scale-gamma", "-1"}).exit_code, 2);
}

TEST(ScancleanCliTest, ScaleRegionsOptionReachesTheFilter) {
  // A plane with a small sphere on it: --scale-regions gives a range of h (the summary shows
  // it); out of range, or without the automatic scale, exit 2 before any work.
  const auto dir = test::make_temp_dir("cli");
  PointCloud cloud = test::noisy_plane(8000, 1.0, 0.002, 37);  // seed 37
  PointCloud ball = test::noisy_sphere(800, 0.04, 0.001, 38);  // seed 38
  for (auto& p : ball.positions) p += Eigen::Vector3d(-0.35, -0.35, 0.1);
  append(cloud, ball);
  cloud.normals.clear();
  write_point_cloud(dir / "in.ply", cloud);
  const ProgramRun one = run_filter_in(dir, {});
  ASSERT_EQ(one.exit_code, 0) << one.err;
  EXPECT_FALSE(contains(one.out, "h range:")) << one.out;
  const ProgramRun regions = run_filter_in(dir, {"--scale-regions", "24"});
  ASSERT_EQ(regions.exit_code, 0) << regions.err;
  EXPECT_TRUE(contains(regions.out, "h range:")) << regions.out;
  fs::remove(dir / "out.ply");
  EXPECT_EQ(run_filter_in(dir, {"--scale-regions", "300"}).exit_code, 2);
  const ProgramRun fixed = run_filter_in(dir, {"--scale-regions", "24", "--h", "0.05"});
  EXPECT_EQ(fixed.exit_code, 2);
  EXPECT_TRUE(contains(fixed.err, "scale_regions")) << fixed.err;
  EXPECT_FALSE(fs::exists(dir / "out.ply"));
}

TEST(ScancleanCliTest, AFixedHThatLeavesMostPointsUnsupportedIsWarnedAbout) {
  // 10,000 points on the unit sphere (spacing about 35 mm, noise 10 mm): h = 50 mm leaves three
  // quarters of them without a kernel. The result is written (exit 0), in memory and tiled, with
  // a warning that names the share and h; the automatic h gives no warning.
  const auto dir = test::make_temp_dir("cli");
  PointCloud cloud = test::noisy_sphere(10000, 1.0, 0.01, 6);  // seed 6
  cloud.normals.clear();
  write_point_cloud(dir / "in.ply", cloud);
  for (const auto& extra : {std::vector<std::string>{"--h", "0.05"},
                            std::vector<std::string>{"--h", "0.05", "--tiled"}}) {
    const ProgramRun r = run_filter_in(dir, extra);
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_TRUE(contains(r.err, "warning") && contains(r.err, "of 10,000 points") &&
                contains(r.err, "h = 50 mm") && contains(r.err, "unsupported"))
        << r.err;
    EXPECT_TRUE(fs::exists(dir / "out.ply"));
    fs::remove(dir / "out.ply");
  }
  const ProgramRun automatic = run_filter_in(dir, {});
  ASSERT_EQ(automatic.exit_code, 0) << automatic.err;
  EXPECT_FALSE(contains(automatic.err, "warning")) << automatic.err;
}

TEST(ScancleanCliTest, DisplacementOptionReachesTheFilter) {
  // Outliers 5-10 sigma off a noisy sphere are pulled onto it; the displacement test (on by
  // default) drops them and the summary counts them; --displacement-sigma 0 keeps them.
  const auto dir = test::make_temp_dir("cli");
  const double sigma = 0.002;
  PointCloud cloud = test::noisy_sphere(8000, 0.3, sigma, 26);  // seed 26
  cloud.normals.clear();
  test::add_shell_outliers(cloud, 100, 0.3, 5 * sigma, 10 * sigma, 27);  // seed 27
  write_point_cloud(dir / "in.ply", cloud);
  auto run_filter = [&](const std::vector<std::string>& extra) {
    return run_filter_in(dir, extra);
  };
  // The count after "displaced " in the summary's outliers line.
  auto displaced = [](const std::string& out) {
    const auto at = out.find("displaced ");
    return at == std::string::npos ? -1L : std::stol(out.substr(at + 10));
  };
  const ProgramRun on = run_filter({});
  ASSERT_EQ(on.exit_code, 0) << on.err;
  EXPECT_GE(displaced(on.out), 15) << on.out;  // measured 25 (64 more are unsupported)
  const ProgramRun off = run_filter({"--displacement-sigma", "0"});
  ASSERT_EQ(off.exit_code, 0) << off.err;
  EXPECT_EQ(displaced(off.out), 0) << off.out;
  EXPECT_EQ(run_filter({"--displacement-sigma", "-1"}).exit_code, 2);
}

TEST(ScancleanCliTest, OrientNormalsGivesACloudWithoutNormalsConsistentOnes) {
  // A noisy sphere without normals: the filter's output normals are PCA normals of either sign;
  // with --orient-normals they follow the estimated, consistently oriented normals, so (nearly) all
  // face the same way, and the points are as close to the sphere as without.
  const auto dir = test::make_temp_dir("cli");
  constexpr double kRadius = 0.3;
  PointCloud cloud = test::noisy_sphere(6000, kRadius, 0.002, 34);  // seed 34
  cloud.normals.clear();
  write_point_cloud(dir / "in.ply", cloud);
  auto outward_share = [](const PointCloud& c) {
    std::size_t out = 0;
    for (std::size_t i = 0; i < c.size(); ++i)
      out += c.normals[i].dot(c.positions[i].cast<float>()) > 0 ? 1 : 0;
    return static_cast<double>(out) / static_cast<double>(std::max<std::size_t>(1, c.size()));
  };
  auto rms_radius = [&](const PointCloud& c) {
    double s = 0;
    for (const auto& p : c.positions) s += (p.norm() - kRadius) * (p.norm() - kRadius);
    return std::sqrt(s / static_cast<double>(std::max<std::size_t>(1, c.size())));
  };
  const ProgramRun plain = run_filter_in(dir, {});
  ASSERT_EQ(plain.exit_code, 0) << plain.err;
  const PointCloud p = read_point_cloud(dir / "out.ply");
  ASSERT_TRUE(p.has_normals());
  const double plain_share = outward_share(p);
  EXPECT_GT(std::min(plain_share, 1 - plain_share), 0.1) << plain_share;  // both signs occur
  const ProgramRun oriented = run_filter_in(dir, {"--orient-normals", "24"});
  ASSERT_EQ(oriented.exit_code, 0) << oriented.err;
  EXPECT_TRUE(contains(oriented.out, "normals:") &&
              contains(oriented.out,
                       "estimated (PCA over 24 neighbours) and oriented (spanning forest over 12)"))
      << oriented.out;
  const PointCloud o = read_point_cloud(dir / "out.ply");
  ASSERT_TRUE(o.has_normals());
  const double share = outward_share(o);
  EXPECT_GT(std::max(share, 1 - share), 0.999) << share;
  EXPECT_LT(rms_radius(o), 1.1 * rms_radius(p));
  // Out of range: exit 2 naming the option, before any work (nothing written).
  fs::remove(dir / "out.ply");
  const ProgramRun bad = run_filter_in(dir, {"--orient-normals", "3"});
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_TRUE(contains(bad.err, "--orient-normals")) << bad.err;
  EXPECT_FALSE(fs::exists(dir / "out.ply"));
  EXPECT_EQ(run_filter_in(dir, {"--orient-normals", "24", "--no-sensor-normals"}).exit_code, 2);
}

TEST(ScancleanCliTest, ViewpointGivesAnOrganizedCloudItsGridsNormalsFacingTheScanner) {
  // A depth camera at the origin looking along +z at a sphere of radius 0.3 m centred 1 m away:
  // an organized 120 x 120 range image of the sphere's near side, noisy along the rays (seed 35),
  // without normals. With --viewpoint 0,0,0 the grid's normals face the camera, and so do the
  // filter's output normals; without, the PCA normals take either sign.
  const auto dir = test::make_temp_dir("cli");
  const Eigen::Vector3d centre(0, 0, 1);
  constexpr double kRadius = 0.3;
  PointCloud cloud;
  cloud.grid.rows = cloud.grid.cols = 120;
  cloud.grid.index.assign(120 * 120, -1);
  std::mt19937 rng(35);
  std::normal_distribution<double> noise(0.0, 0.001);
  for (int r = 0; r < 120; ++r)
    for (int c = 0; c < 120; ++c) {
      const Eigen::Vector3d ray =
          Eigen::Vector3d((c - 60) * 0.003, (r - 60) * 0.003, 1).normalized();
      const double b = ray.dot(centre), disc = b * b - (centre.squaredNorm() - kRadius * kRadius);
      if (disc <= 0) continue;  // the ray misses the sphere: an empty cell
      cloud.grid.index[static_cast<std::size_t>(r) * 120 + c] =
          static_cast<std::int32_t>(cloud.size());
      cloud.positions.push_back((b - std::sqrt(disc) + noise(rng)) * ray);
    }
  ASSERT_GT(cloud.size(), 5000u);
  write_point_cloud(dir / "frame.pcd", cloud);
  auto facing_share = [](const PointCloud& c) {
    std::size_t facing = 0;
    for (std::size_t i = 0; i < c.size(); ++i)
      facing += c.normals[i].cast<double>().dot(-c.positions[i]) > 0 ? 1 : 0;
    return static_cast<double>(facing) / static_cast<double>(std::max<std::size_t>(1, c.size()));
  };
  auto rms_radius = [&](const PointCloud& c) {
    double s = 0;
    for (const auto& p : c.positions) s += std::pow((p - centre).norm() - kRadius, 2);
    return std::sqrt(s / static_cast<double>(std::max<std::size_t>(1, c.size())));
  };
  auto filter = [&](const std::string& in, const std::vector<std::string>& extra) {
    std::vector<std::string> args = {"filter", (dir / in).string(), "-o",
                                     (dir / "out.ply").string()};
    args.insert(args.end(), extra.begin(), extra.end());
    return run(args, dir);
  };
  const ProgramRun plain = filter("frame.pcd", {});
  ASSERT_EQ(plain.exit_code, 0) << plain.err;
  const PointCloud p = read_point_cloud(dir / "out.ply");
  const double plain_share = facing_share(p);
  EXPECT_GT(std::min(plain_share, 1 - plain_share), 0.1) << plain_share;  // both signs occur
  const ProgramRun seen = filter("frame.pcd", {"--viewpoint", "0,0,0"});
  ASSERT_EQ(seen.exit_code, 0) << seen.err;
  EXPECT_TRUE(contains(seen.out, "the range grid, facing the viewpoint (0, 0, 0) m")) << seen.out;
  EXPECT_FALSE(contains(seen.err, "warning")) << seen.err;
  const PointCloud v = read_point_cloud(dir / "out.ply");
  ASSERT_TRUE(v.has_normals());
  EXPECT_GT(facing_share(v), 0.999);
  EXPECT_LT(rms_radius(v), 1.1 * rms_radius(p));
  EXPECT_LT(rms_radius(v), 0.5 * 0.001);  // below the input's noise
  // A viewpoint beside the sphere, which half the grid's normals face away from: warned.
  const ProgramRun beside = filter("frame.pcd", {"--viewpoint", "1,0,0.7"});
  EXPECT_EQ(beside.exit_code, 0) << beside.err;
  EXPECT_TRUE(contains(beside.err, "face the viewpoint")) << beside.err;
  // Unorganized: PCA normals turned to face the viewpoint, the same way.
  cloud.grid = OrganizedGrid{};
  write_point_cloud(dir / "loose.ply", cloud);
  const ProgramRun loose = filter("loose.ply", {"--viewpoint", "0,0,0", "--orient-normals", "24"});
  ASSERT_EQ(loose.exit_code, 0) << loose.err;
  EXPECT_TRUE(contains(loose.out,
                       "estimated (PCA over 24 neighbours) and turned to face the "
                       "viewpoint (0, 0, 0) m"))
      << loose.out;
  const PointCloud l = read_point_cloud(dir / "out.ply");
  EXPECT_GT(facing_share(l), 0.999);
  EXPECT_LT(rms_radius(l), 1.1 * rms_radius(p));
  // Organized and unorganized together, or a bad viewpoint: exit 2 naming the reason, before
  // anything is written.
  fs::remove(dir / "out.ply");
  const ProgramRun mixed =
      run({"filter", (dir / "frame.pcd").string(), (dir / "loose.ply").string(), "-o",
           (dir / "out.ply").string(), "--viewpoint", "0,0,0"},
          dir);
  EXPECT_EQ(mixed.exit_code, 2);
  EXPECT_TRUE(contains(mixed.err, "loose.ply") && contains(mixed.err, "separately")) << mixed.err;
  const ProgramRun two = filter("frame.pcd", {"--viewpoint", "0,0"});
  EXPECT_EQ(two.exit_code, 2);
  EXPECT_TRUE(contains(two.err, "--viewpoint")) << two.err;
  EXPECT_EQ(filter("frame.pcd", {"--viewpoint", "0,0,nan"}).exit_code, 2);
  EXPECT_EQ(filter("frame.pcd", {"--viewpoint", "0,0,0", "--no-sensor-normals"}).exit_code, 2);
  EXPECT_FALSE(fs::exists(dir / "out.ply"));
}

TEST(ScancleanCliTest, UnwritableOutputExitsFourAndLeavesNoFile) {
  const auto dir = test::make_temp_dir("cli");
  write_point_cloud(dir / "in.ply", test::noisy_plane(300, 1.0, 0.001, 5));
  const fs::path out = dir / "no_such_folder" / "out.ply";
  const ProgramRun r = run({"filter", (dir / "in.ply").string(), "-o", out.string()}, dir);
  EXPECT_EQ(r.exit_code, 4) << r.err;
  EXPECT_TRUE(contains(r.err, "no_such_folder")) << r.err;
  EXPECT_FALSE(fs::exists(out));
}
#endif

#ifdef SCANCLEAN_HAVE_OPENNI2
TEST(ScancleanCliTest, CaptureWithoutASensorExitsFiveAndSaysWhatToDo) {
  const auto dir = test::make_temp_dir("cli");
  const ProgramRun r = run({"capture", "-o", (dir / "live.ply").string()}, dir);
  EXPECT_EQ(r.exit_code, 5) << r.err;
  EXPECT_TRUE(contains(r.err, "no depth sensor found; run scanclean devices")) << r.err;
  EXPECT_FALSE(fs::exists(dir / "live.ply"));
}

TEST(ScancleanCliTest, LiveCaptureRecordsEveryFrameAndKeepsTheLatestWindow) {
  const auto dir = test::make_temp_dir("cli");
  const fs::path rec = dir / "rec", latest = dir / "latest.ply", out = dir / "live.ply";
  const ProgramRun r = run(
      {"capture", "--source", "vsensor://pattern?w=160&h=120&n=40&fps=60&pace=realtime", "-o",
       out.string(), "--accumulate", "10", "--record", rec.string(), "--latest", latest.string()},
      dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // Summary: what the sensor delivered, what was recorded and cleaned, the skipped windows and
  // the latency are all stated; the recording holds every delivered frame.
  for (const char* key : {"frames delivered:", "frames recorded:", "frames cleaned:",
                          "windows skipped:", "latency (frame -> window):", "filter phases:"})
    EXPECT_TRUE(contains(r.out, key)) << key << "\n" << r.out;
  const std::string csv = slurp(rec / "frames.csv");
  const auto rows = static_cast<std::size_t>(std::count(csv.begin(), csv.end(), '\n')) - 1;
  // The number after a summary key (the summary aligns its values).
  auto count_of = [&](const std::string& key) -> long long {
    const auto at = r.out.find(key);
    if (at == std::string::npos) return -1;
    std::istringstream line(r.out.substr(at + key.size()));
    long long v = -1;
    line >> v;
    return v;
  };
  EXPECT_EQ(count_of("frames delivered:"), static_cast<long long>(rows)) << r.out;
  EXPECT_EQ(count_of("frames recorded:"), static_cast<long long>(rows)) << r.out;
  EXPECT_EQ(count_of("windows skipped:"), 0) << r.out;
  // The latest window is the last numbered output.
  const PointCloud last = read_point_cloud(latest);
  EXPECT_FALSE(last.empty());
  const fs::path last_window = dir / ("live_000" + std::to_string((rows - 1) / 10) + ".ply");
  ASSERT_TRUE(fs::exists(last_window)) << last_window;
  EXPECT_EQ(read_point_cloud(last_window).positions, last.positions);
  // A second capture into the same recording folder is refused before anything is read.
  const ProgramRun again = run({"capture", "--source", "vsensor://pattern?w=160&h=120&n=5", "-o",
                                (dir / "x.ply").string(), "--record", rec.string()},
                               dir);
  EXPECT_EQ(again.exit_code, 4) << again.err;
  EXPECT_TRUE(contains(again.err, "already holds a recording")) << again.err;
}

TEST(ScancleanCliTest, CtrlCStopsACaptureMidWindowCleansWhatWasCapturedAndExits130) {
  const auto dir = test::make_temp_dir("cli");
  const fs::path out = dir / "live.ply", rec = dir / "rec", log = dir / "capture.log";
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) {
      ::dup2(fd, 1);
      ::dup2(fd, 2);
    }
    ::execl(SCANCLEAN_PROGRAM, SCANCLEAN_PROGRAM, "capture", "--source",
            "vsensor://pattern?w=160&h=120&n=3000&fps=30&pace=realtime", "-o", out.c_str(),
            "--accumulate", "1000", "--record", rec.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  // Interrupt once some frames were recorded (a window of 1000 frames is then half-way at most).
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  std::size_t rows = 0;
  while (std::chrono::steady_clock::now() < deadline && rows < 20) {
    const std::string csv = slurp(rec / "frames.csv");
    rows = csv.empty() ? 0 : static_cast<std::size_t>(std::count(csv.begin(), csv.end(), '\n'));
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ASSERT_EQ(::kill(child, SIGINT), 0);
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status)) << slurp(log);
  EXPECT_EQ(WEXITSTATUS(status), 130) << slurp(log);
  const std::string text = slurp(log);
  EXPECT_TRUE(contains(text, "interrupted")) << text;
  // What was captured is cleaned and written: one partial window, every frame recorded.
  ASSERT_TRUE(fs::exists(out)) << text;
  EXPECT_FALSE(read_point_cloud(out).empty());
  const std::string csv = slurp(rec / "frames.csv");
  const auto recorded = static_cast<long long>(std::count(csv.begin(), csv.end(), '\n')) - 1;
  EXPECT_GE(recorded, 19);
  EXPECT_LT(recorded, 1000);
  EXPECT_TRUE(contains(text, "frames recorded:")) << text;
}

TEST(ScancleanCliTest, ReplayOfTheBundledRecordingWritesAnOrganizedRawFrame) {
  const auto dir = test::make_temp_dir("cli");
  const fs::path oni = test::recordings_dir() / "oni" / "3dj_test.oni";
  const fs::path out = dir / "frame.ply";
  const ProgramRun r =
      run({"replay", oni.string(), "--frames", "0:1", "--raw", "-o", out.string()}, dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const PointCloud cloud = read_point_cloud(out);
  EXPECT_GT(cloud.size(), 150000u);  // a 640x480 PrimeSense frame of a room: ~210k valid pixels
  EXPECT_LT(cloud.size(), 640u * 480u);
  EXPECT_TRUE(cloud.has_normals());
  EXPECT_TRUE(cloud.has_confidences());
  for (const auto& p : cloud.positions) {
    ASSERT_GT(p.z(), 0.3);  // metres, in front of the camera, within the PS1080's range
    ASSERT_LT(p.z(), 10.5);
  }
}

TEST(ScancleanCliTest, ReplayFusesFramesAndWritesWhatTheFilterRemoved) {
  const auto dir = test::make_temp_dir("cli");
  const fs::path oni = test::recordings_dir() / "oni" / "3dj_test.oni";
  const fs::path out = dir / "near.ply", removed = dir / "removed.ply";
  // Three frames of the near part of the scene (up to 1.5 m), no merging: every fused point
  // is either in the output or in the outliers file.
  const ProgramRun r = run({"replay", oni.string(), "--frames", "0:3", "--max-depth", "1.5",
                            "--merge-eps", "0", "-o", out.string(), "--outliers", removed.string()},
                           dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto at = r.out.find("fused per pixel:");
  ASSERT_NE(at, std::string::npos) << r.out;
  std::string digits;
  for (std::size_t k = at + 16; k < r.out.size() && r.out[k] != '('; ++k)
    if (std::isdigit(static_cast<unsigned char>(r.out[k]))) digits += r.out[k];
  const std::size_t fused = std::stoul(digits);
  const PointCloud kept = read_point_cloud(out), dropped = read_point_cloud(removed);
  EXPECT_EQ(kept.size() + dropped.size(), fused);
  EXPECT_GT(kept.size(), 60000u);         // about 69k valid pixels per frame up to 1.5 m
  EXPECT_LT(dropped.size(), fused / 20);  // a few per cent at most: edges and stray pixels
  for (const auto& p : kept.positions) ASSERT_LT(p.z(), 1.5 + 0.05);
}
#endif

#ifdef SCANCLEAN_HAVE_SL
TEST(ScancleanCliTest, SlPatternsWritesTheWholeSequence) {
  const auto dir = test::make_temp_dir("cli");
  const ProgramRun r =
      run({"sl", "patterns", "--projector", "64x32", "-o", (dir / "rig").string()}, dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(dir / "rig" / "capture.json"));
  std::size_t images = 0;
  for (const auto& entry : fs::directory_iterator(dir / "rig" / "patterns"))
    images += entry.path().extension() == ".png";
  EXPECT_EQ(images, 2u * (6 + 5) + 2);  // 6 column + 5 row bits with inverses, white, black
  const ProgramRun bad =
      run({"sl", "patterns", "--projector", "64by32", "-o", (dir / "x").string()}, dir);
  EXPECT_EQ(bad.exit_code, 2) << bad.err;
}
#endif

}  // namespace
}  // namespace scanclean

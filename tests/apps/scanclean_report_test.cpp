// --report FILE.json and the provenance header comment, end to end: the report is parsed back
// and its fields are checked against the printed summary, the files and an independent SHA-256
// (coreutils' sha256sum); a bad report path stops the run before any work.

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "scanclean/io/point_cloud_io.h"
#include "support/data_paths.h"
#include "support/program_run.h"
#include "support/synthetic.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace scanclean {
namespace {

test::ProgramRun run(const std::vector<std::string>& args, const fs::path& dir) {
  return test::run_program(SCANCLEAN_PROGRAM, args, dir);
}

// "  key:   text" lines of the summary printed on stdout.
std::vector<std::pair<std::string, std::string>> summary_lines(const std::string& out) {
  std::vector<std::pair<std::string, std::string>> lines;
  std::istringstream in(out);
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("  ", 0) != 0) continue;
    const auto colon = line.find(": ");
    if (colon == std::string::npos) continue;
    std::string key = line.substr(2, colon - 2);
    std::string text = line.substr(colon + 1);
    text.erase(0, text.find_first_not_of(' '));
    lines.emplace_back(key, text);
  }
  return lines;
}

std::string sha256sum(const fs::path& file, const fs::path& dir) {
  const auto r = test::run_program("/usr/bin/sha256sum", {file.string()}, dir);
  if (r.exit_code != 0) return "sha256sum failed: " + r.err;
  return r.out.substr(0, 64);
}

// The first header comment that carries the provenance ("... command: ...").
std::string provenance_comment(const fs::path& ply) {
  std::ifstream in(ply, std::ios::binary);
  for (std::string line; std::getline(in, line) && line != "end_header";)
    if (line.rfind("comment ", 0) == 0 && line.find("command: ") != std::string::npos) return line;
  return {};
}

TEST(ScancleanReportTest, FilterReportHoldsTheSummaryOptionsFilesAndHashes) {
  if (!fs::exists("/usr/bin/sha256sum")) GTEST_SKIP() << "sha256sum (coreutils) not available";
  const auto dir = test::make_temp_dir("report");
  PointCloud cloud = test::noisy_plane(3000, 1.0, 0.004, 31);
  cloud.normals.clear();
  test::add_uniform_outliers(cloud, 30, -0.5, 0.5, 32);
  write_point_cloud(dir / "in.ply", cloud);
  const fs::path out = dir / "clean.ply", removed = dir / "removed.pcd", rep = dir / "run.json";
  const auto r = run({"filter", (dir / "in.ply").string(), "-o", out.string(), "--outliers",
                      removed.string(), "--tau", "0.2", "--threads", "2", "--report", rep.string()},
                     dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::ifstream f(rep);
  ASSERT_TRUE(f.good()) << "no report written";
  const json j = json::parse(f);
  EXPECT_EQ(j["version"], "0.1.0");
  EXPECT_EQ(j["command"], "filter");
  EXPECT_EQ(j["exit_code"], 0);
  EXPECT_TRUE(j["error"].is_null());
  // Options in force: the typed ones as typed, the others at their defaults.
  EXPECT_EQ(j["options"]["--tau"], "0.2");
  EXPECT_EQ(j["options"]["--threads"], "2");
  EXPECT_EQ(j["options"]["--outlier-sigma"], "4");
  EXPECT_EQ(j["options"]["--ascii"], false);
  // Input and outputs: sizes and SHA-256 as coreutils computes them.
  ASSERT_EQ(j["inputs"].size(), 1u);
  EXPECT_EQ(j["inputs"][0]["bytes"], fs::file_size(dir / "in.ply"));
  EXPECT_EQ(j["inputs"][0]["sha256"], sha256sum(dir / "in.ply", dir));
  ASSERT_EQ(j["outputs"].size(), 2u);
  for (const auto& o : j["outputs"]) {
    const fs::path p = o["path"].get<std::string>();
    EXPECT_EQ(o["bytes"], fs::file_size(p)) << p;
    EXPECT_EQ(o["sha256"], sha256sum(p, dir)) << p;
  }
  // Every summary line printed is in the report, with the same text; numbers unrounded.
  ASSERT_EQ(j["summaries"].size(), 1u);
  const json& lines = j["summaries"][0]["lines"];
  const auto printed = summary_lines(r.out);
  ASSERT_GT(printed.size(), 10u) << r.out;
  EXPECT_EQ(lines.size(), printed.size());
  for (const auto& [key, text] : printed) {
    ASSERT_TRUE(lines.contains(key)) << key;
    EXPECT_EQ(lines[key]["text"], text) << key;
  }
  const PointCloud clean = read_point_cloud(out), dropped = read_point_cloud(removed);
  EXPECT_EQ(lines["points out"]["value"], clean.size());
  EXPECT_EQ(lines["points in"]["value"], cloud.size());
  // The filter statistics: counts that add up, h in metres equal to the summary's mm.
  ASSERT_EQ(j["filter"].size(), 1u);
  const json& s = j["filter"][0];
  EXPECT_EQ(s["points_out"], clean.size());
  EXPECT_EQ(s["removed"], dropped.size());
  const double h = s["h_m"];
  EXPECT_NEAR(lines["h"]["value"].get<double>(), h * 1000.0, 1e-9);
  EXPECT_EQ(lines["h"]["unit"], "mm");
  EXPECT_GT(j["timings"]["run_s"].get<double>(), 0.0);
  // Provenance in the written header: h (as the mesh command reads it back) and the command.
  const std::string comment = provenance_comment(out);
  char expected_h[48];
  std::snprintf(expected_h, sizeof expected_h, "h=%.6g m", h);
  EXPECT_NE(comment.find(expected_h), std::string::npos) << comment;
  EXPECT_NE(comment.find("noise_sigma="), std::string::npos) << comment;
  EXPECT_NE(comment.find("command: scanclean filter"), std::string::npos) << comment;
  EXPECT_NE(comment.find("--tau 0.2"), std::string::npos) << comment;
}

TEST(ScancleanReportTest, BadReportPathStopsBeforeAnyWork) {
  const auto dir = test::make_temp_dir("report");
  write_point_cloud(dir / "in.ply", test::noisy_plane(500, 1.0, 0.004, 33));
  const std::string in = (dir / "in.ply").string(), out = (dir / "out.ply").string();
  auto r = run({"filter", in, "-o", out, "--report", (dir / "run.txt").string()}, dir);
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find(".json"), std::string::npos) << r.err;
  r = run({"filter", in, "-o", out, "--report", (dir / "missing" / "run.json").string()}, dir);
  EXPECT_EQ(r.exit_code, 4) << r.err;
  EXPECT_NE(r.err.find("missing"), std::string::npos) << r.err;
  r = run({"filter", in, "-o", out, "--report", out}, dir);
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_FALSE(fs::exists(out)) << "the filter ran although the report path was refused";
}

TEST(ScancleanReportTest, FailedRunStillReportsItsExitCodeAndError) {
  const auto dir = test::make_temp_dir("report");
  {
    std::ofstream bad(dir / "bad.ply");
    bad << "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nend_header\n1\n";
  }
  const fs::path rep = dir / "run.json";
  const auto r = run({"filter", (dir / "bad.ply").string(), "-o", (dir / "out.ply").string(),
                      "--report", rep.string()},
                     dir);
  EXPECT_EQ(r.exit_code, 3) << r.err;
  std::ifstream f(rep);
  ASSERT_TRUE(f.good());
  const json j = json::parse(f);
  EXPECT_EQ(j["exit_code"], 3);
  ASSERT_TRUE(j["error"].is_string());
  EXPECT_NE(j["error"].get<std::string>().find("bad.ply"), std::string::npos) << j["error"];
  EXPECT_TRUE(j["summaries"].empty());
}

#if defined(SCANCLEAN_HAVE_FILTER)
TEST(ScancleanReportTest, ReplayReportListsTheSourceAndTheFilterRun) {
  const auto dir = test::make_temp_dir("report");
  const fs::path oni = test::recordings_dir() / "oni" / "3dj_test.oni";
  const fs::path out = dir / "near.ply", rep = dir / "replay.json";
  const auto r = run({"replay", oni.string(), "--frames", "0:2", "--max-depth", "1.2", "-o",
                      out.string(), "--report", rep.string()},
                     dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::ifstream f(rep);
  const json j = json::parse(f);
  EXPECT_EQ(j["command"], "replay");
  EXPECT_EQ(j["options"]["--frames"], "0:2");
  EXPECT_EQ(j["options"]["--scale-gamma"], "0");  // the depth-frame preset
  ASSERT_EQ(j["inputs"].size(), 1u);
  EXPECT_EQ(j["inputs"][0]["bytes"], fs::file_size(oni));
  ASSERT_EQ(j["filter"].size(), 1u);
  const PointCloud clean = read_point_cloud(out);
  EXPECT_EQ(j["filter"][0]["points_out"], clean.size());
  EXPECT_EQ(j["summaries"][0]["lines"]["points out"]["value"], clean.size());
  EXPECT_EQ(j["summaries"][0]["lines"]["frames used"]["value"], 2);
  const std::string comment = provenance_comment(out);
  EXPECT_NE(comment.find("command: scanclean replay"), std::string::npos) << comment;
  EXPECT_NE(comment.find("h="), std::string::npos) << comment;
}
#endif

}  // namespace
}  // namespace scanclean

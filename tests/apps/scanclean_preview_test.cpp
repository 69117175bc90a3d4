// --preview FILE.png end to end: the picture is decoded with OpenCV and checked for what it must
// show (the removed points in magenta on the left, displacement colours both ways on the right),
// and a bad path stops the run before any work.

#include <gtest/gtest.h>

#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "scanclean/io/point_cloud_io.h"
#include "support/data_paths.h"
#include "support/program_run.h"
#include "support/synthetic.h"

namespace fs = std::filesystem;

namespace scanclean {
namespace {

test::ProgramRun run(const std::vector<std::string>& args, const fs::path& dir) {
  return test::run_program(SCANCLEAN_PROGRAM, args, dir);
}

struct Counts {
  std::size_t magenta = 0, reddish = 0, bluish = 0;
};

Counts count_colours(const cv::Mat& img, int x0, int x1) {
  Counts c;
  for (int y = 30; y < img.rows - 96; ++y)
    for (int x = x0; x < x1; ++x) {
      const cv::Vec3b p = img.at<cv::Vec3b>(y, x);  // BGR
      if (p[0] == 255 && p[1] == 0 && p[2] == 255) ++c.magenta;
      if (p[2] > p[0] + 40 && p[2] > p[1] + 40) ++c.reddish;
      if (p[0] > p[2] + 40 && p[0] > p[1] + 20) ++c.bluish;
    }
  return c;
}

TEST(ScancleanPreviewTest, FilterPreviewShowsRemovedPointsAndDisplacementBothWays) {
  const auto dir = test::make_temp_dir("preview");
  PointCloud cloud = test::noisy_plane(4000, 1.0, 0.004, 51);
  cloud.normals.clear();
  test::add_uniform_outliers(cloud, 40, -0.5, 0.5, 52);
  write_point_cloud(dir / "in.ply", cloud);
  const fs::path png = dir / "preview.png";
  const auto r = run({"filter", (dir / "in.ply").string(), "-o", (dir / "out.ply").string(),
                      "--preview", png.string(), "--threads", "2"},
                     dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("preview:"), std::string::npos) << r.out;
  const cv::Mat img = cv::imread(png.string(), cv::IMREAD_COLOR);
  ASSERT_FALSE(img.empty()) << "not a readable PNG";
  EXPECT_EQ(img.cols, 2 * 720 + 6);
  EXPECT_EQ(img.rows, 2 * (30 + 540) + 96);  // the whole view and a 3x detail
  const Counts left = count_colours(img, 0, 720), right = count_colours(img, 726, img.cols);
  EXPECT_GT(left.magenta, 20u) << "the removed points are not marked";
  EXPECT_EQ(right.magenta, 0u);
  // Noise on both sides of the plane: points moved both ways along the normal.
  EXPECT_GT(right.reddish, 500u);
  EXPECT_GT(right.bluish, 500u);
  EXPECT_EQ(left.reddish, 0u) << "the input panel is grey";
}

TEST(ScancleanPreviewTest, BadPreviewPathStopsBeforeAnyWork) {
  const auto dir = test::make_temp_dir("preview");
  write_point_cloud(dir / "in.ply", test::noisy_plane(500, 1.0, 0.004, 53));
  const std::string in = (dir / "in.ply").string(), out = (dir / "out.ply").string();
  auto r = run({"filter", in, "-o", out, "--preview", (dir / "p.jpg").string()}, dir);
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find(".png"), std::string::npos) << r.err;
  r = run({"filter", in, "-o", out, "--preview", (dir / "nope" / "p.png").string()}, dir);
  EXPECT_EQ(r.exit_code, 4) << r.err;
  EXPECT_FALSE(fs::exists(out));
}

TEST(ScancleanColourTest, OrganizedPcdColoursReachTheFilteredOutput) {
  const fs::path pcd =
      test::shared_data_dir() / "pcl_test_clouds/table_scene_mug_stereo_textured.pcd";
  if (!fs::exists(pcd)) GTEST_SKIP() << "shared data not available: " << pcd;
  const auto dir = test::make_temp_dir("colour");
  const fs::path out = dir / "clean.ply";
  const auto r = run({"filter", pcd.string(), "-o", out.string(), "--threads", "2"}, dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const PointCloud in = read_point_cloud(pcd), clean = read_point_cloud(out);
  ASSERT_TRUE(in.has_colors());
  ASSERT_TRUE(clean.has_colors());
  const Attribute* src = clean.find_attribute("source_index");
  const Attribute* mc = clean.find_attribute("merge_count");
  ASSERT_NE(src, nullptr);
  ASSERT_NE(mc, nullptr);
  std::size_t single = 0;
  for (std::size_t k = 0; k < clean.size(); ++k) {
    if (mc->values[k] != 1) continue;  // merged points carry their members' mean colour
    ++single;
    ASSERT_EQ(clean.colors[k], in.colors[static_cast<std::size_t>(src->values[k])]) << k;
  }
  EXPECT_GT(single, clean.size() / 2);
}

#if defined(SCANCLEAN_HAVE_FILTER)
TEST(ScancleanPreviewTest, ReplayPreviewOfTheBundledRecording) {
  const auto dir = test::make_temp_dir("preview");
  const fs::path oni = test::recordings_dir() / "oni" / "3dj_test.oni";
  const fs::path png = dir / "oni.png";
  const auto r = run({"replay", oni.string(), "--frames", "0:2", "--max-depth", "1.2", "-o",
                      (dir / "near.ply").string(), "--preview", png.string()},
                     dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const cv::Mat img = cv::imread(png.string(), cv::IMREAD_COLOR);
  ASSERT_FALSE(img.empty());
  const Counts left = count_colours(img, 0, 720), right = count_colours(img, 726, img.cols);
  EXPECT_GT(left.magenta, 0u);
  EXPECT_GT(right.reddish + right.bluish, 1000u);
  // --raw has no filter to show.
  const auto raw = run({"replay", oni.string(), "--frames", "0:1", "--raw", "-o",
                        (dir / "raw.ply").string(), "--preview", (dir / "raw.png").string()},
                       dir);
  EXPECT_EQ(raw.exit_code, 2) << raw.err;
}
#endif

}  // namespace
}  // namespace scanclean

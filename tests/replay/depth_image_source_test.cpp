#include "scanclean/replay/depth_image_source.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "scanclean/core/errors.h"
#include "support/data_paths.h"

namespace scanclean {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

struct DepthStats {
  std::size_t valid = 0, invalid = 0;
  double min_m = 0, max_m = 0;
  std::uint16_t min_raw = 0, max_raw = 0;
};

DepthStats stats(const RangeFrame& f) {
  DepthStats s;
  std::uint16_t lo = 65535, hi = 0;
  for (std::uint16_t v : f.depth.data) {
    if (v == 0) {
      ++s.invalid;
      continue;
    }
    ++s.valid;
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  s.min_raw = lo;
  s.max_raw = hi;
  s.min_m = lo * f.depth_unit_m;
  s.max_m = hi * f.depth_unit_m;
  return s;
}

DepthImageOptions with_k(double fx, double fy, double cx, double cy, std::string format = "auto") {
  DepthImageOptions o;
  o.format = std::move(format);
  Intrinsics K;
  K.fx = fx;
  K.fy = fy;
  K.cx = cx;
  K.cy = cy;
  o.K = K;
  return o;
}

std::vector<RangeFrame> read_all(RangeSource& src) {
  std::vector<RangeFrame> frames;
  RangeFrame f;
  ReadStatus st;
  while ((st = src.next(f, 0ms)) == ReadStatus::kOk) frames.push_back(f);
  EXPECT_EQ(st, ReadStatus::kEndOfStream);
  EXPECT_EQ(src.next(f, 0ms), ReadStatus::kEndOfStream);  // reported again
  return frames;
}

// ---- real files from ../shared/data (PROVENANCE.md §4 and §6) ----

TEST(DepthImageSourceTest, TumPngAutoDetectedAt5000PerMetre) {
  SCANCLEAN_REQUIRE_SHARED("rgbd_frames/open3d_tum_sample/TUM_depth.png");
  auto src = make_depth_image_source(test::shared_data_dir() / "rgbd_frames/open3d_tum_sample",
                                     with_k(525, 525, 319.5, 239.5));
  src->open();
  EXPECT_EQ(src->info().kind, "depth-images");
  EXPECT_DOUBLE_EQ(src->info().depth_unit_m, 1.0 / 5000);
  EXPECT_EQ(src->info().name.rfind("tum:", 0), 0u) << src->info().name;
  EXPECT_NE(src->info().name.find("46655"), std::string::npos) << src->info().name;
  const auto frames = read_all(*src);  // TUM_color.png is skipped
  ASSERT_EQ(frames.size(), 1u);
  const DepthStats s = stats(frames[0]);
  EXPECT_EQ(s.valid, 248250u);  // 80.8 %
  EXPECT_NEAR(static_cast<double>(s.valid) / frames[0].depth.size(), 0.81, 0.005);
  EXPECT_EQ(s.min_raw, 7320);
  EXPECT_EQ(s.max_raw, 46655);
  EXPECT_NEAR(s.min_m, 1.464, 1e-9);
  EXPECT_NEAR(s.max_m, 9.331, 1e-9);
  EXPECT_EQ(frames[0].K.width, 640);
  EXPECT_EQ(frames[0].K.height, 480);
}

TEST(DepthImageSourceTest, ColourImagesBesideTheDepthBecomeTheFramesColour) {
  SCANCLEAN_REQUIRE_SHARED("rgbd_frames/open3d_tum_sample/TUM_color.png");
  SCANCLEAN_REQUIRE_SHARED("rgbd_frames/redwood_livingroom1_synthetic/color/00000.jpg");
  // TUM_depth.png + TUM_color.png (same folder), Redwood depth/ + color/ (sibling folders).
  const fs::path tum = test::shared_data_dir() / "rgbd_frames/open3d_tum_sample";
  auto src = make_depth_image_source(tum / "TUM_depth.png", with_k(525, 525, 319.5, 239.5));
  src->open();
  EXPECT_NE(src->info().name.find("colour from TUM_color.png"), std::string::npos)
      << src->info().name;
  const auto frames = read_all(*src);
  ASSERT_EQ(frames.size(), 1u);
  ASSERT_TRUE(frames[0].color.has_value());
  const cv::Mat bgr = cv::imread((tum / "TUM_color.png").string(), cv::IMREAD_COLOR);
  ASSERT_EQ(frames[0].color->width, bgr.cols);
  for (const auto& [u, v] : {std::pair{0, 0}, std::pair{320, 240}, std::pair{639, 479}}) {
    const cv::Vec3b p = bgr.at<cv::Vec3b>(v, u);
    const auto& c = (*frames[0].color)(u, v);
    EXPECT_EQ(c[0], p[2]);
    EXPECT_EQ(c[1], p[1]);
    EXPECT_EQ(c[2], p[0]);
  }
  auto redwood = make_depth_image_source(
      test::shared_data_dir() / "rgbd_frames/redwood_livingroom1_synthetic", {});
  redwood->open();
  RangeFrame f;
  ASSERT_EQ(redwood->next(f, 0ms), ReadStatus::kOk);
  ASSERT_TRUE(f.color.has_value());
  EXPECT_EQ(f.color->width, f.depth.width);
}

TEST(DepthImageSourceTest, SlambookBigEndianPgmInMillimetres) {
  SCANCLEAN_REQUIRE_SHARED("rgbd_frames/slambook_joinmap/depth/1.pgm");
  // The folder has color/ and depth/; the source finds depth/ and orders 1..5 numerically.
  auto src = make_depth_image_source(test::shared_data_dir() / "rgbd_frames/slambook_joinmap",
                                     with_k(518.0, 519.0, 325.5, 253.5));
  src->open();
  EXPECT_EQ(src->info().name.rfind("mm:", 0), 0u) << src->info().name;
  EXPECT_NE(src->info().name.find("big-endian"), std::string::npos) << src->info().name;
  const auto frames = read_all(*src);
  ASSERT_EQ(frames.size(), 5u);
  const DepthStats s = stats(frames[0]);
  EXPECT_EQ(s.min_raw, 946);
  EXPECT_EQ(s.max_raw, 9823);
  EXPECT_EQ(s.valid, 209236u);
  EXPECT_NEAR(static_cast<double>(s.valid) / frames[0].depth.size(), 0.68, 0.005);
  EXPECT_DOUBLE_EQ(frames[0].depth_unit_m, 0.001);
  EXPECT_EQ(stats(frames[3]).min_raw, 713);  // 4.pgm (PROVENANCE inventory)
  for (std::size_t i = 1; i < frames.size(); ++i) {
    EXPECT_EQ(frames[i].index, i);
    EXPECT_GT(frames[i].device_ts_us, frames[i - 1].device_ts_us);
  }
  EXPECT_EQ(frames[4].K.fx, 518.0);
}

TEST(DepthImageSourceTest, NyuLittleEndianDisparityConvertedToMillimetres) {
  SCANCLEAN_REQUIRE_SHARED("rgbd_frames/open3d_nyu_sample/NYU_depth.pgm");
  const fs::path file = test::shared_data_dir() / "rgbd_frames/open3d_nyu_sample/NYU_depth.pgm";
  for (const char* format : {"auto", "nyu"}) {
    auto src = make_depth_image_source(file, with_k(525, 525, 319.5, 239.5, format));
    src->open();
    EXPECT_EQ(src->info().name.rfind("nyu:", 0), 0u) << src->info().name;
    EXPECT_EQ(src->info().noise_model, "nguyen2012");
    const auto frames = read_all(*src);
    ASSERT_EQ(frames.size(), 1u);
    const DepthStats s = stats(frames[0]);
    EXPECT_EQ(s.invalid, 22199u);  // raw 2047
    EXPECT_NEAR(s.min_m, 1.39, 0.005);
    EXPECT_NEAR(s.max_m, 6.69, 0.005);
    EXPECT_DOUBLE_EQ(frames[0].depth_unit_m, 0.001);
  }
  // Read as a standard (big-endian) millimetre PGM on request: nonsense, but as asked.
  auto mm = make_depth_image_source(file, with_k(525, 525, 319.5, 239.5, "mm"));
  mm->open();
  const auto frames = read_all(*mm);
  EXPECT_GT(stats(frames[0]).max_raw, 60000);  // byte-swapped 2047 = 0xFF07
}

TEST(DepthImageSourceTest, PclGrabberTiffInMillimetres) {
  SCANCLEAN_REQUIRE_SHARED("pcl_grabber_sequence/tiff");
  auto src = make_depth_image_source(test::shared_data_dir() / "pcl_grabber_sequence/tiff",
                                     with_k(525, 525, 320, 240));
  src->open();
  const auto frames = read_all(*src);  // the *_rgb.tiff files are skipped
  ASSERT_EQ(frames.size(), 2u);
  const DepthStats s = stats(frames[0]);
  EXPECT_EQ(s.valid, 271575u);
  EXPECT_EQ(s.min_raw, 671);
  EXPECT_EQ(s.max_raw, 1713);
  EXPECT_EQ(stats(frames[1]).valid, 271395u);
  // Timestamps from the names: 14:22:56.068683 - 14:22:55.814212 = 254471 us.
  EXPECT_EQ(frames[1].device_ts_us - frames[0].device_ts_us, 254471);
  // The *_rgb.tiff beside each depth image is the frame's colour, pixel for pixel.
  const cv::Mat bgr = cv::imread(
      (test::shared_data_dir() / "pcl_grabber_sequence/tiff/frame_20121214T142256.068683_rgb.tiff")
          .string(),
      cv::IMREAD_COLOR);
  ASSERT_FALSE(bgr.empty());
  ASSERT_TRUE(frames[1].color.has_value());
  ASSERT_EQ(frames[1].color->width, bgr.cols);
  ASSERT_EQ(frames[1].color->height, bgr.rows);
  std::size_t differ = 0;
  for (int v = 0; v < bgr.rows; v += 7)
    for (int u = 0; u < bgr.cols; u += 5) {
      const cv::Vec3b p = bgr.at<cv::Vec3b>(v, u);
      const std::array<std::uint8_t, 3> rgb{p[2], p[1], p[0]};
      differ += (*frames[1].color)(u, v) != rgb;
    }
  EXPECT_EQ(differ, 0u);
}

TEST(DepthImageSourceTest, RedwoodUsesOpen3dIntrinsicsSidecar) {
  SCANCLEAN_REQUIRE_SHARED("rgbd_frames/redwood_livingroom1_synthetic/depth/00000.png");
  auto src = make_depth_image_source(test::shared_data_dir() /
                                     "rgbd_frames/redwood_livingroom1_synthetic");
  src->open();  // no intrinsics passed: camera_primesense.json is found in the parent folder
  EXPECT_EQ(src->info().K.fx, 525.0);
  EXPECT_EQ(src->info().K.cx, 319.5);
  EXPECT_EQ(src->info().K.cy, 239.5);
  EXPECT_NE(src->info().name.find("camera_primesense.json"), std::string::npos);
  const auto frames = read_all(*src);
  ASSERT_EQ(frames.size(), 5u);
  EXPECT_EQ(stats(frames[0]).min_raw, 955);
  EXPECT_EQ(stats(frames[0]).max_raw, 2702);
  EXPECT_EQ(stats(frames[4]).valid, 269051u);
}

// ---- synthetic files: exact oracles ----

void write_pgm16(const fs::path& p, int w, int h, const std::vector<std::uint16_t>& v,
                 bool little_endian, const std::string& header_extra = "") {
  std::ofstream out(p, std::ios::binary);
  out << "P5\n" << header_extra << w << " " << h << "\n65535\n";
  for (std::uint16_t x : v) {
    const char hi = static_cast<char>(x >> 8), lo = static_cast<char>(x & 0xFF);
    if (little_endian) {
      out.put(lo);
      out.put(hi);
    } else {
      out.put(hi);
      out.put(lo);
    }
  }
}

//! A smooth ramp (what real depth looks like locally) plus holes.
std::vector<std::uint16_t> ramp(int w, int h, int base, int step, int hole_value) {
  std::vector<std::uint16_t> v(static_cast<std::size_t>(w) * h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      v[static_cast<std::size_t>(y) * w + x] =
          (x + y) % 11 == 0 ? static_cast<std::uint16_t>(hole_value)
                            : static_cast<std::uint16_t>(base + step * (x + 2 * y));
  return v;
}

TEST(DepthImageSourceTest, NyuConversionFollowsTheFormula) {
  const auto dir = test::make_temp_dir("nyu_synth");
  const int w = 40, h = 30;
  const auto raw = ramp(w, h, 600, 1, 2047);  // disparities 600..709, holes = 2047
  write_pgm16(dir / "d.pgm", w, h, raw, /*little_endian=*/true, "# NYU-like\n");
  auto src = make_depth_image_source(dir / "d.pgm", with_k(500, 500, 20, 15));
  src->open();
  EXPECT_EQ(src->info().name.rfind("nyu:", 0), 0u) << src->info().name;
  const auto frames = read_all(*src);
  ASSERT_EQ(frames.size(), 1u);
  for (std::size_t k = 0; k < raw.size(); ++k) {
    if (raw[k] == 2047) {
      EXPECT_EQ(frames[0].depth.data[k], 0);
      continue;
    }
    const double mm = 351.3 / (1092.5 - raw[k]) * 1000.0;
    EXPECT_NEAR(frames[0].depth.data[k], mm, 0.5) << "raw " << raw[k];
  }
  fs::remove_all(dir);
}

TEST(DepthImageSourceTest, PgmByteOrderDetectedBothWays) {
  const auto dir = test::make_temp_dir("pgm_order");
  const int w = 32, h = 24;
  const auto mm = ramp(w, h, 3000, 3, 0);  // 3000.. mm, holes 0
  write_pgm16(dir / "be.pgm", w, h, mm, false);
  write_pgm16(dir / "le.pgm", w, h, mm, true);
  for (const char* name : {"be.pgm", "le.pgm"}) {
    auto src = make_depth_image_source(dir / name, with_k(500, 500, 16, 12));
    src->open();
    EXPECT_EQ(src->info().name.rfind("mm:", 0), 0u) << src->info().name;
    const auto frames = read_all(*src);
    ASSERT_EQ(frames.size(), 1u);
    EXPECT_EQ(frames[0].depth.data, mm) << name;  // both byte orders recovered exactly
  }
  fs::remove_all(dir);
}

TEST(DepthImageSourceTest, SidecarGivesIntrinsicsAndFormat) {
  const auto dir = test::make_temp_dir("sidecar");
  const auto v = ramp(20, 10, 1000, 2, 0);
  cv::Mat m(10, 20, CV_16UC1, const_cast<std::uint16_t*>(v.data()));
  ASSERT_TRUE(cv::imwrite((dir / "10.png").string(), m));
  ASSERT_TRUE(cv::imwrite((dir / "2.png").string(), m));
  ASSERT_TRUE(cv::imwrite((dir / "1305031102.160407.png").string(), m));
  std::ofstream(dir / "intrinsics.json")
      << R"({"fx": 300.5, "fy": 301, "cx": 9.5, "cy": 4.5, "width": 20, "height": 10,
             "depth_scale": 5000, "noise_model": "none"})";
  auto src = make_depth_image_source(dir);
  src->open();
  const SourceInfo info = src->info();
  EXPECT_EQ(info.K.fx, 300.5);
  EXPECT_EQ(info.K.cy, 4.5);
  EXPECT_EQ(info.K.source, "calibration");
  EXPECT_DOUBLE_EQ(info.depth_unit_m, 1.0 / 5000);  // small values, yet TUM: the sidecar says so
  EXPECT_EQ(info.noise_model, "none");
  ASSERT_TRUE(info.frame_count);
  EXPECT_EQ(*info.frame_count, 3u);
  const auto frames = read_all(*src);
  ASSERT_EQ(frames.size(), 3u);
  EXPECT_EQ(frames[0].depth.data, v);
  // Names are not all timestamps: nominal 30 fps timestamps by position.
  EXPECT_EQ(frames[1].device_ts_us, 33333);
  // The command line overrides the sidecar.
  auto cli = make_depth_image_source(dir, with_k(111, 112, 10, 5, "mm"));
  cli->open();
  EXPECT_EQ(cli->info().K.fx, 111);
  EXPECT_DOUBLE_EQ(cli->info().depth_unit_m, 0.001);
  // A sidecar with only the format: intrinsics must come from the command line.
  std::ofstream(dir / "intrinsics.json", std::ios::trunc) << R"({"format": "mm"})";
  auto no_k = make_depth_image_source(dir);
  EXPECT_THROW(no_k->open(), OptionError);
  auto only_format = make_depth_image_source(dir, with_k(111, 112, 10, 5));
  only_format->open();
  EXPECT_DOUBLE_EQ(only_format->info().depth_unit_m, 0.001);
  EXPECT_NE(only_format->info().name.find("from intrinsics.json"), std::string::npos)
      << only_format->info().name;
  // A K whose size differs from the images is an InputError.
  DepthImageOptions wrong = with_k(111, 112, 10, 5);
  wrong.K->width = 640;
  wrong.K->height = 480;
  auto bad = make_depth_image_source(dir, wrong);
  EXPECT_THROW(bad->open(), InputError);
  fs::remove_all(dir);
}

TEST(DepthImageSourceTest, NaturalOrderAndTumTimestamps) {
  EXPECT_TRUE(natural_less("2.png", "10.png"));
  EXPECT_FALSE(natural_less("10.png", "2.png"));
  EXPECT_TRUE(natural_less("frame_9_depth.png", "frame_10_depth.png"));
  EXPECT_TRUE(natural_less("00001.png", "00002.png"));
  EXPECT_TRUE(natural_less("a.png", "b.png"));
  const auto dir = test::make_temp_dir("tum_names");
  const auto v = ramp(8, 6, 20000, 5, 0);
  cv::Mat m(6, 8, CV_16UC1, const_cast<std::uint16_t*>(v.data()));
  for (const char* n : {"1305031102.160407.png", "1305031102.194330.png", "1305031102.226738.png"})
    ASSERT_TRUE(cv::imwrite((dir / n).string(), m));
  auto src = make_depth_image_source(dir, with_k(500, 500, 4, 3));
  src->open();
  const auto frames = read_all(*src);
  ASSERT_EQ(frames.size(), 3u);
  EXPECT_EQ(frames[0].device_ts_us, 1305031102160407LL);
  EXPECT_EQ(frames[1].device_ts_us - frames[0].device_ts_us, 33923);
  EXPECT_EQ(frames[2].device_ts_us - frames[1].device_ts_us, 32408);
  fs::remove_all(dir);
}

// A TUM RGB-D sequence: depth/ and rgb/ named by their own timestamps. Each depth image takes
// the colour image nearest in time (within 20 ms); one farther away means no colour at all.
TEST(DepthImageSourceTest, TumSequenceColourPairedByTimestamp) {
  const auto dir = test::make_temp_dir("tum_seq");
  fs::create_directories(dir / "depth");
  fs::create_directories(dir / "rgb");
  const auto v = ramp(8, 6, 20000, 5, 0);
  const cv::Mat depth(6, 8, CV_16UC1, const_cast<std::uint16_t*>(v.data()));
  for (const char* n : {"1305031102.160407.png", "1305031102.194330.png"})
    ASSERT_TRUE(cv::imwrite((dir / "depth" / n).string(), depth));
  // Colour frames 5 ms before, 8 ms after and 1 s after: blue, green and red (BGR on disk).
  const std::vector<std::pair<std::string, cv::Scalar>> rgb = {
      {"1305031102.155001.png", {255, 0, 0}},
      {"1305031102.202330.png", {0, 255, 0}},
      {"1305031103.202330.png", {0, 0, 255}}};
  for (const auto& [n, bgr] : rgb)
    ASSERT_TRUE(cv::imwrite((dir / "rgb" / n).string(), cv::Mat(6, 8, CV_8UC3, bgr)));
  {
    auto src = make_depth_image_source(dir, with_k(500, 500, 4, 3));
    src->open();
    EXPECT_NE(src->info().name.find("colour from 1305031102.155001.png"), std::string::npos)
        << src->info().name;
    const auto frames = read_all(*src);
    ASSERT_EQ(frames.size(), 2u);
    ASSERT_TRUE(frames[0].color.has_value() && frames[1].color.has_value());
    const std::array<std::uint8_t, 3> blue{0, 0, 255}, green{0, 255, 0};
    EXPECT_EQ((*frames[0].color)(3, 2), blue);
    EXPECT_EQ((*frames[1].color)(3, 2), green);
  }
  // The second depth image's nearest colour now 30 ms away: no colour for the sequence.
  fs::remove(dir / "rgb" / "1305031102.202330.png");
  ASSERT_TRUE(cv::imwrite((dir / "rgb" / "1305031102.224330.png").string(),
                          cv::Mat(6, 8, CV_8UC3, cv::Scalar(0, 255, 0))));
  auto src = make_depth_image_source(dir, with_k(500, 500, 4, 3));
  src->open();
  const auto frames = read_all(*src);
  ASSERT_EQ(frames.size(), 2u);
  EXPECT_FALSE(frames[0].color.has_value());
  fs::remove_all(dir);
}

TEST(DepthImageSourceTest, MissingIntrinsicsSayHowToPassThem) {
  const auto dir = test::make_temp_dir("noK");
  const auto v = ramp(8, 6, 1000, 5, 0);
  cv::Mat m(6, 8, CV_16UC1, const_cast<std::uint16_t*>(v.data()));
  ASSERT_TRUE(cv::imwrite((dir / "a.png").string(), m));
  auto src = make_depth_image_source(dir / "a.png");
  try {
    src->open();
    FAIL() << "opened without intrinsics";
  } catch (const OptionError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("--fx --fy --cx --cy"), std::string::npos) << msg;
    EXPECT_NE(msg.find("intrinsics.json"), std::string::npos) << msg;
    EXPECT_NE(msg.find((dir / "a.png").string()), std::string::npos) << msg;
  }
  fs::remove_all(dir);
}

//! expects InputError naming `file` (and containing `needle`) when opening or reading all.
void expect_bad(const fs::path& path, const DepthImageOptions& o, const std::string& needle) {
  try {
    auto src = make_depth_image_source(path, o);
    src->open();
    read_all(*src);
    ADD_FAILURE() << "accepted " << path << " (expected: " << needle << ")";
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(path.filename().string()), std::string::npos) << msg;
    EXPECT_NE(msg.find(needle), std::string::npos) << msg;
  }
}

TEST(DepthImageSourceTest, BadImagesGiveInputErrorsNamingTheFile) {
  const auto dir = test::make_temp_dir("bad_depth");
  const DepthImageOptions o = with_k(500, 500, 4, 3);
  cv::imwrite((dir / "eight.png").string(), cv::Mat(6, 8, CV_8UC1, cv::Scalar(9)));
  expect_bad(dir / "eight.png", o, "8-bit grayscale");
  cv::imwrite((dir / "three.png").string(), cv::Mat(6, 8, CV_16UC3, cv::Scalar(9, 9, 9)));
  expect_bad(dir / "three.png", o, "16-bit RGB");
  cv::imwrite((dir / "three.tiff").string(), cv::Mat(6, 8, CV_8UC3, cv::Scalar(9, 9, 9)));
  expect_bad(dir / "three.tiff", o, "3 channel(s) of 8 bits");
  std::ofstream(dir / "eight.pgm", std::ios::binary) << "P5\n2 2\n255\nabcd";
  expect_bad(dir / "eight.pgm", o, "8-bit PGM");
  std::ofstream(dir / "short.pgm", std::ios::binary) << "P5\n4 4\n65535\nabcd";
  expect_bad(dir / "short.pgm", o, "truncated PGM");
  std::ofstream(dir / "huge.pgm", std::ios::binary) << "P5\n999999 999999\n65535\nabcd";
  expect_bad(dir / "huge.pgm", o, "implausible size");
  std::ofstream(dir / "ascii.pgm", std::ios::binary) << "P2\n2 2\n65535\n1 2 3 4\n";
  expect_bad(dir / "ascii.pgm", o, "P5");
  {  // A TIFF whose header claims 100000 x 100000 pixels: refused before decoding.
    std::vector<unsigned char> tif;
    cv::imencode(".tiff", cv::Mat(6, 8, CV_16UC1, cv::Scalar(900)), tif);
    ASSERT_GT(tif.size(), 8u);
    ASSERT_EQ(tif[0], 'I');  // OpenCV writes little-endian TIFF
    const std::size_t ifd = tif[4] | (tif[5] << 8) | (tif[6] << 16) | (tif[7] << 24);
    const std::size_t n = tif[ifd] | (tif[ifd + 1] << 8);
    for (std::size_t k = 0; k < n; ++k) {
      unsigned char* e = &tif[ifd + 2 + k * 12];
      const int tag = e[0] | (e[1] << 8);
      if (tag != 256 && tag != 257) continue;
      e[2] = 4;  // LONG
      e[3] = 0;
      const std::uint32_t big = 100000;
      for (int i = 0; i < 4; ++i) e[8 + i] = static_cast<unsigned char>(big >> (8 * i));
    }
    std::ofstream(dir / "lying.tiff", std::ios::binary)
        .write(reinterpret_cast<const char*>(tif.data()), static_cast<std::streamsize>(tif.size()));
    expect_bad(dir / "lying.tiff", o, "implausible image size 100000x100000");
  }
  // A sequence whose second image has another size.
  fs::create_directories(dir / "seq");
  cv::imwrite((dir / "seq/1.png").string(), cv::Mat(6, 8, CV_16UC1, cv::Scalar(900)));
  cv::imwrite((dir / "seq/2.png").string(), cv::Mat(7, 8, CV_16UC1, cv::Scalar(900)));
  expect_bad(dir / "seq", o, "2.png");
  // tum on a PGM, nyu on a PNG: contradictions are named.
  write_pgm16(dir / "x.pgm", 2, 2, {1, 2, 3, 4}, false);
  expect_bad(dir / "x.pgm", with_k(500, 500, 1, 1, "tum"), "format tum");
  expect_bad(dir / "seq/1.png", with_k(500, 500, 4, 3, "nyu"), "format nyu");
  // Missing path and an empty folder.
  expect_bad(dir / "nope", o, "no such file");
  fs::create_directories(dir / "empty");
  expect_bad(dir / "empty", o, "no depth image");
  fs::remove_all(dir);
}

TEST(DepthImageSourceTest, OptionsAreValidated) {
  DepthImageOptions o;
  o.format = "kinect";
  EXPECT_THROW(validate(o), OptionError);
  o = with_k(-1, 500, 0, 0);
  EXPECT_THROW(validate(o), OptionError);
  o = {};
  o.frame_period_s = 0;
  EXPECT_THROW(validate(o), OptionError);
  o = {};
  o.noise_model = "gauss";
  EXPECT_THROW(validate(o), OptionError);
  EXPECT_NO_THROW(validate(DepthImageOptions{}));
}

}  // namespace
}  // namespace scanclean

// Capture folders and calibration files: pattern generation, the kamino410 layout, and clear
// InputErrors for bad captures (missing images, wrong sizes, inconsistent counts, calibrations
// with missing fields).

#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <regex>
#include <string>

#include "scanclean/core/errors.h"
#include "scanclean/drivers/sl_calibration.h"
#include "scanclean/drivers/sl_capture.h"
#include "scanclean/drivers/sl_decode.h"
#include "scanclean/drivers/structured_light_source.h"
#include "sl_fixtures.h"
#include "support/data_paths.h"

namespace scanclean {
namespace {
namespace fs = std::filesystem;

// A small valid capture (projector 64x48 -> 6 + 6 bits, camera 80x60), rendered once.
struct Small {
  SlCalibration calib;
  test::SlRendered rendered;
};
const Small& small() {
  static const Small s = [] {
    Small x;
    x.calib = test::make_sl_calibration();
    x.calib.camera.width = 80;
    x.calib.camera.height = 60;
    x.calib.camera.cx = 39.5;
    x.calib.camera.cy = 29.5;
    x.calib.camera.fx = x.calib.camera.fy = 125;
    x.calib.projector.width = 64;
    x.calib.projector.height = 48;
    x.calib.projector.cx = 31.5;
    x.calib.projector.cy = 23.5;
    x.calib.projector.fx = x.calib.projector.fy = 64;
    test::SlScene scene;
    scene.with_sphere = false;
    x.rendered = test::render_sl_capture(x.calib, scene);
    return x;
  }();
  return s;
}

fs::path write_small(const std::string& tag) {
  const fs::path folder = test::make_temp_dir(tag) / "cap";
  test::write_sl_capture(folder, small().calib, small().rendered.images);
  return folder;
}

// Runs f, expects an InputError whose message contains every fragment.
template <class F>
void expect_input_error(F&& f, const std::vector<std::string>& fragments) {
  try {
    f();
    ADD_FAILURE() << "no InputError thrown";
  } catch (const InputError& e) {
    const std::string msg = e.what();
    for (const auto& frag : fragments)
      EXPECT_NE(msg.find(frag), std::string::npos) << "message: " << msg << "\nmissing: " << frag;
  }
}

TEST(SlFormatTest, PatternsCommandWritesOpenCVSequenceAndDescription) {
  const fs::path dir = test::make_temp_dir("sl_patterns");
  const int n = write_graycode_patterns(dir, 100, 40, 7, 33);
  EXPECT_EQ(n, 2 * (7 + 6) + 2);  // ceil(log2 100) = 7, ceil(log2 40) = 6, + white + black
  nlohmann::json j;
  std::ifstream(dir / "capture.json") >> j;
  EXPECT_EQ(j["count"], 26);
  EXPECT_EQ(j["white_index"], 26);
  EXPECT_EQ(j["black_index"], 27);
  EXPECT_EQ(j["thresholds"]["white"], 7);
  EXPECT_EQ(j["thresholds"]["black"], 33);
  // Pattern 0 is the column MSB: columns >= 64 lit; pattern 1 its inverse; white, black last.
  const cv::Mat p0 = cv::imread((dir / "patterns" / "000.png").string(), cv::IMREAD_UNCHANGED);
  const cv::Mat p1 = cv::imread((dir / "patterns" / "001.png").string(), cv::IMREAD_UNCHANGED);
  const cv::Mat w = cv::imread((dir / "patterns" / "026.png").string(), cv::IMREAD_UNCHANGED);
  const cv::Mat b = cv::imread((dir / "patterns" / "027.png").string(), cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(p0.empty() || p1.empty() || w.empty() || b.empty());
  EXPECT_EQ(p0.cols, 100);
  EXPECT_EQ(p0.rows, 40);
  EXPECT_EQ(p0.type(), CV_8UC1);
  EXPECT_EQ(p0.at<std::uint8_t>(5, 63), 0);
  EXPECT_EQ(p0.at<std::uint8_t>(5, 64), 255);
  EXPECT_EQ(cv::countNonZero(p0 + p1 != 255), 0);
  EXPECT_EQ(cv::countNonZero(w != 255), 0);
  EXPECT_EQ(cv::countNonZero(b), 0);
}

TEST(SlFormatTest, CalibrationRoundTrip) {
  const fs::path file = test::make_temp_dir("sl_calib") / "calib.yml";
  SlCalibration c = test::make_sl_calibration();
  c.graycode_step = 2;
  write_sl_calibration(file, c);
  const SlCalibration r = read_sl_calibration(file);
  EXPECT_EQ(r.layout, "scanclean");
  EXPECT_DOUBLE_EQ(r.camera.fx, c.camera.fx);
  EXPECT_DOUBLE_EQ(r.projector.cy, c.projector.cy);
  EXPECT_EQ(r.camera.dist, c.camera.dist);
  EXPECT_EQ(r.projector.width, 800);
  EXPECT_TRUE(r.R.isApprox(c.R, 1e-12));
  EXPECT_TRUE(r.T.isApprox(c.T, 1e-12));
  EXPECT_DOUBLE_EQ(r.unit_m, 0.001);
  EXPECT_FALSE(r.unit_assumed);
  EXPECT_EQ(r.graycode_step, 2);
}

TEST(SlFormatTest, CalibrationWithMissingFieldNamesIt) {
  const fs::path dir = test::make_temp_dir("sl_calib_missing");
  {
    cv::FileStorage fs((dir / "calib.yml").string(), cv::FileStorage::WRITE);
    fs << "cam_K" << cv::Mat::eye(3, 3, CV_64F) << "cam_dist" << cv::Mat::zeros(1, 5, CV_64F);
    fs << "proj_K" << cv::Mat::eye(3, 3, CV_64F);
  }
  expect_input_error([&] { read_sl_calibration(dir / "calib.yml"); },
                     {"calib.yml", "proj_dist", "missing"});
  {
    cv::FileStorage fs((dir / "calibration_result.xml").string(), cv::FileStorage::WRITE);
    fs << "cam_int" << cv::Mat::eye(3, 3, CV_64F) << "cam_dist" << cv::Mat::zeros(1, 5, CV_64F);
    fs << "proj_int" << cv::Mat::eye(3, 3, CV_64F) << "proj_dist" << cv::Mat::zeros(1, 5, CV_64F);
    fs << "translation" << cv::Mat::zeros(3, 1, CV_64F);
  }
  expect_input_error([&] { read_sl_calibration(dir / "calibration_result.xml"); },
                     {"calibration_result.xml", "roration", "missing"});
  {
    cv::FileStorage fs((dir / "bad_k.yml").string(), cv::FileStorage::WRITE);
    fs << "cam_K" << cv::Mat::eye(2, 3, CV_64F);
  }
  expect_input_error([&] { read_sl_calibration(dir / "bad_k.yml"); },
                     {"bad_k.yml", "cam_K", "3x3"});
  expect_input_error([&] { read_sl_calibration(dir / "absent.yml"); }, {"absent.yml", "not found"});
}

TEST(SlFormatTest, MissingImageIsNamed) {
  const fs::path folder = write_small("sl_missing");
  fs::remove(folder / "img" / "007.png");
  const SlCaptureInfo info = describe_sl_capture(folder);
  expect_input_error([&] { SlCapture::load(info); }, {"007.png", "missing", "pattern image 7"});
  auto src = make_structured_light_source(folder);
  src->open();
  RangeFrame f;
  EXPECT_EQ(src->next(f, std::chrono::milliseconds(0)), ReadStatus::kError);
  EXPECT_NE(src->last_error().find("007.png"), std::string::npos) << src->last_error();
}

TEST(SlFormatTest, WrongImageSizeIsNamed) {
  const fs::path folder = write_small("sl_size");
  cv::imwrite((folder / "img" / "012.png").string(), cv::Mat(61, 80, CV_8U, cv::Scalar(9)));
  expect_input_error([&] { SlCapture::load(describe_sl_capture(folder)); },
                     {"012.png", "80x61", "expected 80x60"});
  // A consistent capture of the wrong size for the calibration.
  const fs::path other = write_small("sl_size_calib");
  SlCalibration c = small().calib;
  c.camera.width = 160;
  c.camera.height = 120;
  write_sl_calibration(other / "calib.yml", c);
  expect_input_error([&] { process_sl_capture(other); }, {"000.png", "80x60", "160x120"});
}

TEST(SlFormatTest, InconsistentCountIsNamed) {
  const fs::path folder = write_small("sl_count");
  nlohmann::json j;
  std::ifstream(folder / "capture.json") >> j;
  j["count"] = 22;
  std::ofstream(folder / "capture.json") << j.dump();
  expect_input_error([&] { describe_sl_capture(folder); },
                     {"capture.json", "count", "22", "needs 24"});
  j["count"] = 24;
  j.erase("projector");
  std::ofstream(folder / "capture.json") << j.dump();
  expect_input_error([&] { describe_sl_capture(folder); },
                     {"capture.json", "projector", "missing"});
  std::ofstream(folder / "capture.json") << "{\"format\": ";
  expect_input_error([&] { describe_sl_capture(folder); }, {"capture.json", "invalid JSON"});
}

// Numbers JSON can hold but the program cannot: 1e400 (no finite double), integers beyond int,
// fractions where an integer is expected, negative exposure. Each is named; none reaches a cast.
TEST(SlFormatTest, OutOfRangeNumbersAreNamed) {
  const fs::path folder = write_small("sl_range");
  std::string text;
  {
    std::ifstream in(folder / "capture.json");
    text.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  const fs::path file = folder / "capture.json";
  EXPECT_NO_THROW(parse_sl_capture_description(text, file));
  const auto with = [&](const std::string& key, const std::string& value) {
    nlohmann::json j = nlohmann::json::parse(text);
    j[key] = nlohmann::json::parse(value);
    return j.dump();
  };
  std::string t = text;
  t.insert(t.rfind('}'), ", \"exposure_us\": 1e400");
  expect_input_error([&] { parse_sl_capture_description(t, file); },
                     {"capture.json", "out of range", "finite"});
  expect_input_error([&] { parse_sl_capture_description(with("count", "24.5"), file); },
                     {"capture.json", "count", "expected an integer", "24.5"});
  expect_input_error([&] { parse_sl_capture_description(with("count", "1e10"), file); },
                     {"capture.json", "count", "expected an integer"});
  expect_input_error([&] { parse_sl_capture_description(with("white_index", "4294967296"), file); },
                     {"capture.json", "white_index", "out of range"});
  expect_input_error(
      [&] { parse_sl_capture_description(with("black_index", "-9223372036854775807"), file); },
      {"capture.json", "black_index", "out of range"});
  expect_input_error([&] { parse_sl_capture_description(with("exposure_us", "-5"), file); },
                     {"capture.json", "exposure_us", ">= 0"});
  // The folder path reads the same text through the same checks.
  std::ofstream(file, std::ios::binary | std::ios::trunc) << t;
  expect_input_error([&] { describe_sl_capture(folder); }, {"capture.json", "out of range"});
}

TEST(SlFormatTest, OversizedCaptureDescriptionIsRefused) {
  const fs::path folder = write_small("sl_big_json");
  {
    std::ofstream out(folder / "capture.json", std::ios::binary | std::ios::trunc);
    out << "{\"pad\": \"" << std::string(70000, 'x') << "\"}";
  }
  expect_input_error([&] { describe_sl_capture(folder); },
                     {"capture.json", "larger than 65536 bytes"});
}

TEST(SlFormatTest, NoCalibrationIsNamed) {
  const fs::path folder = write_small("sl_nocalib");
  fs::remove(folder / "calib.yml");
  expect_input_error([&] { process_sl_capture(folder); }, {"cap", "no calibration", "--calib"});
  const fs::path empty = test::make_temp_dir("sl_empty");
  expect_input_error([&] { make_structured_light_source(empty)->open(); },
                     {"sl_empty", "no structured-light capture"});
}

// Hand-made intensities: Gray -> binary, ties (I == I_inverse reads 0, as OpenCV), the margin
// and contrast rules, and out-of-range codes, for both decoders.
TEST(SlFormatTest, HandMadePixelsDecodeAsSpecified) {
  SlCaptureInfo info;
  info.graycode = graycode_layout(3, 2);  // 2 column bits, 1 row bit; code 3 is out of range
  info.white_index = 6;
  info.black_index = 7;
  // Per pixel: column Gray bits (MSB first), row bit; '+' lit, '-' inverse lit, '=' tie.
  const std::vector<std::string> codes = {"++-", "===", "+--", "-+-", "-++", "++-"};
  const std::vector<int> black = {10, 10, 10, 10, 10, 80};
  std::vector<Image<std::uint8_t>> images(8, Image<std::uint8_t>(6, 1));
  for (int x = 0; x < 6; ++x) {
    for (int b = 0; b < 3; ++b) {
      const char ch = codes[static_cast<std::size_t>(x)][static_cast<std::size_t>(b)];
      const std::uint8_t hi = 200, lo = static_cast<std::uint8_t>(x == 3 ? 197 : 20);
      images[static_cast<std::size_t>(2 * b)](x, 0) = ch == '-' ? lo : (ch == '=' ? 100 : hi);
      images[static_cast<std::size_t>(2 * b + 1)](x, 0) = ch == '+' ? lo : (ch == '=' ? 100 : hi);
    }
    images[6](x, 0) = 210;
    images[7](x, 0) = static_cast<std::uint8_t>(black[static_cast<std::size_t>(x)]);
  }
  const SlCapture cap = SlCapture::from_images(info, images);
  for (SlDecoder decoder : {SlDecoder::kFast, SlDecoder::kOpenCV}) {
    SlDecodeOptions o;
    o.decoder = decoder;
    o.white_threshold = 5;
    o.black_threshold = 150;
    o.sub_stripe = false;  // the integer decode's rules (sub-stripe: SlSubStripeTest)
    const SlDecoded d = decode_graycode(cap, o);
    SCOPED_TRACE(to_string(decoder));
    // x=0: Gray 11 -> binary 10 = column 2, row 0.
    EXPECT_EQ(d.status(0, 0), 0);
    EXPECT_EQ(d.column(0, 0), 2);
    EXPECT_EQ(d.row(0, 0), 0);
    EXPECT_FLOAT_EQ(d.confidence(0, 0), 180.0f / 200.0f);
    EXPECT_EQ(d.status(1, 0), static_cast<std::uint8_t>(SlPixelStatus::kWeakBit));  // ties
    EXPECT_EQ(d.column(1, 0), -1);
    EXPECT_EQ(d.confidence(1, 0), 0.0f);
    EXPECT_EQ(d.status(2, 0), static_cast<std::uint8_t>(SlPixelStatus::kOutOfRange));  // 3 >= 3
    EXPECT_EQ(d.status(3, 0), static_cast<std::uint8_t>(SlPixelStatus::kWeakBit));     // margin 3
    EXPECT_EQ(d.status(4, 0), 0);  // Gray 01 -> binary 01 = column 1; row 1
    EXPECT_EQ(d.column(4, 0), 1);
    EXPECT_EQ(d.row(4, 0), 1);
    EXPECT_EQ(d.status(5, 0), static_cast<std::uint8_t>(SlPixelStatus::kShadow));  // 130 <= 150
    EXPECT_EQ(d.lit, 5u);
  }
  // With white threshold 0 a tie is a readable 0 bit: column 0, row 0, confidence 0.
  for (SlDecoder decoder : {SlDecoder::kFast, SlDecoder::kOpenCV}) {
    SlDecodeOptions o;
    o.decoder = decoder;
    o.white_threshold = 0;
    o.black_threshold = 150;
    o.sub_stripe = false;  // the integer decode's rules (sub-stripe: SlSubStripeTest)
    const SlDecoded d = decode_graycode(cap, o);
    EXPECT_EQ(d.status(1, 0), 0) << to_string(decoder);
    EXPECT_EQ(d.column(1, 0), 0);
    EXPECT_EQ(d.row(1, 0), 0);
    EXPECT_EQ(d.confidence(1, 0), 0.0f);
  }
}

TEST(SlFormatTest, Kamino410LayoutGivesTheSameFrame) {
  const fs::path folder = write_small("sl_kamino_ref");
  const SlResult ref = process_sl_capture(folder);
  // The same images and calibration in the kamino410 layout: graycode_NN.png, the calibration
  // with kamino410's field names in the parent folder, the projector size from the options.
  const fs::path root = test::make_temp_dir("sl_kamino");
  const fs::path cap = root / "capture_0";
  fs::create_directories(cap);
  const auto& images = small().rendered.images;
  for (std::size_t k = 0; k < images.size(); ++k) {
    char name[40];
    std::snprintf(name, sizeof name, "graycode_%02zu.png", k);
    fs::copy_file(ref.info.images[k], cap / name);
  }
  {
    const SlCalibration& c = small().calib;
    cv::FileStorage fs((root / "calibration_result.xml").string(), cv::FileStorage::WRITE);
    auto K = [](const Intrinsics& k) -> cv::Mat {
      return (cv::Mat_<double>(3, 3) << k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1);
    };
    auto D = [](const Intrinsics& k) -> cv::Mat {
      return (cv::Mat_<double>(1, 5) << k.dist[0], k.dist[1], k.dist[2], k.dist[3], k.dist[4]);
    };
    cv::Mat R(3, 3, CV_64F), T(3, 1, CV_64F);
    for (int i = 0; i < 3; ++i) {
      T.at<double>(i) = c.T(i);
      for (int j = 0; j < 3; ++j) R.at<double>(i, j) = c.R(i, j);
    }
    fs << "img_shape" << (cv::Mat_<double>(2, 1) << c.camera.height, c.camera.width);
    fs << "rms" << 0.5 << "cam_int" << K(c.camera) << "cam_dist" << D(c.camera);
    fs << "proj_int" << K(c.projector) << "proj_dist" << D(c.projector);
    fs << "roration" << R << "translation" << T;
  }
  EXPECT_TRUE(is_structured_light_capture(cap));
  expect_input_error([&] { describe_sl_capture(cap); }, {"projector size unknown", "--projector"});
  SlOptions o;
  o.projector_width = 64;
  o.projector_height = 48;
  const SlResult k = process_sl_capture(cap, o);
  EXPECT_EQ(k.info.layout, "kamino410");
  EXPECT_EQ(k.calibration.layout, "kamino410");
  EXPECT_TRUE(k.calibration.unit_assumed);
  EXPECT_TRUE(k.graycode_step_estimated);
  EXPECT_EQ(k.calibration.graycode_step, 1);  // the step that fits this calibration
  ASSERT_GT(ref.triangulation.points, 1000u);
  EXPECT_EQ(k.triangulation.points, ref.triangulation.points);
  std::size_t differ = 0;
  for (std::size_t i = 0; i < ref.frame.points->size(); ++i) {
    const auto& a = ref.frame.points->data[i];
    const auto& b = k.frame.points->data[i];
    differ += a.allFinite() != b.allFinite() || (a.allFinite() && (a - b).norm() > 1e-6f);
  }
  EXPECT_EQ(differ, 0u);
  // A gap in the numbering is a missing image, named.
  fs::remove(cap / "graycode_05.png");
  expect_input_error([&] { describe_sl_capture(cap, 64, 48); }, {"graycode_05.png", "missing"});
}

}  // namespace
}  // namespace scanclean

// Calibration text from untrusted bytes: parse_sl_calibration reads the YAML and XML layouts
// with its own strict reader (OpenCV's FileStorage parser crashes, loops or allocates without
// bound on small malformed files). Every malformed input is an InputError naming the file and
// the place; the layouts that cv::FileStorage and kamino410 write are read exactly.

#include <gtest/gtest.h>

#include <fstream>
#include <iterator>
#include <random>

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "scanclean/core/errors.h"
#include "scanclean/drivers/sl_calibration.h"
#include "sl_fixtures.h"
#include "support/data_paths.h"

namespace scanclean {
namespace {

void expect_parse_error(const std::string& text, const std::vector<std::string>& fragments) {
  try {
    parse_sl_calibration(text, "bad.yml");
    ADD_FAILURE() << "no InputError for:\n" << text;
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("bad.yml"), std::string::npos) << msg;
    for (const auto& f : fragments)
      EXPECT_NE(msg.find(f), std::string::npos) << "message: " << msg << "\nmissing: " << f;
  }
}

std::string written_by_opencv(const SlCalibration& c) {
  const auto file = test::make_temp_dir("sl_parse") / "calib.yml";
  write_sl_calibration(file, c);
  std::ifstream in(file);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

TEST(SlCalibrationParseTest, ReadsWhatOpenCVWritesYamlAndXml) {
  const SlCalibration c = test::make_sl_calibration();
  const SlCalibration y = parse_sl_calibration(written_by_opencv(c), "calib.yml");
  EXPECT_EQ(y.layout, "scanclean");
  EXPECT_DOUBLE_EQ(y.camera.fx, c.camera.fx);
  EXPECT_EQ(y.projector.dist, c.projector.dist);
  EXPECT_TRUE(y.R.isApprox(c.R, 1e-15));
  EXPECT_DOUBLE_EQ(y.unit_m, 0.001);
  // The same fields through OpenCV's XML writer.
  cv::FileStorage fs(".xml", cv::FileStorage::WRITE | cv::FileStorage::MEMORY);
  cv::Mat K =
      (cv::Mat_<double>(3, 3) << c.camera.fx, 0, c.camera.cx, 0, c.camera.fy, c.camera.cy, 0, 0, 1);
  cv::Mat P = (cv::Mat_<double>(3, 3) << c.projector.fx, 0, c.projector.cx, 0, c.projector.fy,
               c.projector.cy, 0, 0, 1);
  cv::Mat R(3, 3, CV_64F), T(3, 1, CV_64F);
  for (int i = 0; i < 3; ++i) {
    T.at<double>(i) = c.T(i);
    for (int j = 0; j < 3; ++j) R.at<double>(i, j) = c.R(i, j);
  }
  fs << "cam_K" << K << "cam_dist" << cv::Mat::zeros(1, 5, CV_64F) << "proj_K" << P << "proj_dist"
     << cv::Mat::zeros(1, 5, CV_64F) << "R" << R << "T" << T;
  fs << "cam_size" << std::vector<int>{640, 480} << "proj_size" << std::vector<int>{800, 600};
  fs << "units" << std::string("mm") << "rms" << 0.25;
  const SlCalibration x = parse_sl_calibration(fs.releaseAndGetString(), "calib.xml");
  EXPECT_DOUBLE_EQ(x.projector.cy, c.projector.cy);
  EXPECT_EQ(x.camera.width, 640);
  EXPECT_EQ(x.projector.height, 600);
  EXPECT_TRUE(x.T.isApprox(c.T, 1e-15));
  EXPECT_DOUBLE_EQ(x.rms, 0.25);
}

TEST(SlCalibrationParseTest, KaminoLayoutRoundTrip) {
  SlCalibration c = test::make_sl_calibration();
  c.unit_m = 1.0;  // metres in, millimetres in the kamino410 file
  c.T *= 0.001;
  const auto file = test::make_temp_dir("sl_parse_kamino") / "calibration_result.xml";
  write_sl_calibration_kamino(file, c);
  const SlCalibration r = read_sl_calibration(file);
  EXPECT_EQ(r.layout, "kamino410");
  EXPECT_TRUE(r.unit_assumed);
  EXPECT_NEAR((r.T * r.unit_m - c.T).norm(), 0.0, 1e-12);
  EXPECT_DOUBLE_EQ(r.projector.fx, c.projector.fx);
  EXPECT_EQ(r.camera.width, 640);
  EXPECT_EQ(r.camera.height, 480);
}

TEST(SlCalibrationParseTest, ReadsTheShippedKaminoFile) {
  SCANCLEAN_REQUIRE_SHARED("structured_light_kamino410/calibration_result.xml");
  const SlCalibration c = read_sl_calibration(test::shared_data_dir() /
                                              "structured_light_kamino410/calibration_result.xml");
  EXPECT_NEAR(c.camera.fx, 3452.39, 0.01);
  EXPECT_NEAR(c.projector.cy, 1357.83, 0.01);
  EXPECT_NEAR(c.T.x(), 85.737, 0.001);
  EXPECT_EQ(c.camera.width, 1280);
}

TEST(SlCalibrationParseTest, MalformedTextIsAnInputErrorWithThePlace) {
  const std::string head = "<?xml version=\"1.0\"?>\n<opencv_storage>\n";
  // Truncated XML (OpenCV 4.6 dereferences NULL on files like this).
  expect_parse_error(head + "<cam_int type_id=\"opencv-matrix\"><rows>3</rows><cols>3</co",
                     {"line 3"});
  expect_parse_error(head + "<a>1</b>\n</opencv_storage>\n", {"line 3", "</a>"});
  expect_parse_error(head + "<a type_id=\"opencv-matrix\"><rows>abc</rows></a>\n", {"rows"});
  // A huge or non-numeric size (OpenCV allocates tens of GB or throws length_error).
  expect_parse_error(
      "cam_K: !!opencv-matrix\n   rows: 100000000\n   cols: 3\n   dt: d\n"
      "   data: [ 1. ]\n",
      {"line 2", "rows must be an integer 1..16"});
  expect_parse_error("cam_K: !!opencv-matrix\n   rows: x9\n   cols: 3\n   dt: d\n   data: [ 1. ]\n",
                     {"line 2", "rows"});
  expect_parse_error(
      "cam_K: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 1., 2. ]\n",
      {"line 1", "cam_K", "2 values"});
  // NUL bytes (OpenCV loops forever on small files with them).
  expect_parse_error(std::string("%YAML:1.0\nrms: 1\0\0\0", 18), {"byte 0", "printable ASCII"});
  expect_parse_error("\x89PNG\r\n\x1a\n", {"byte 137"});
  expect_parse_error(
      "cam_K: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 1., 0.,\n",
      {"line 5", "'[' without ']'"});
  expect_parse_error("rms: 1\nrms: 2\n", {"line 2", "appears twice"});
  expect_parse_error("T: [ 1, nan, 3 ]\n", {"line 1", "non-finite"});
  expect_parse_error("T: [ 1, 1e999, 3 ]\n", {"line 1", "non-finite"});
  expect_parse_error("T: [ 1, 0x10, 3 ]\n", {"line 1", "expected a number"});
  expect_parse_error("  indented: 1\n", {"line 1", "indentation"});
  expect_parse_error("", {"cam_K", "missing"});
  expect_parse_error(head, {"missing </opencv_storage>"});
  expect_parse_error(std::string(2 << 20, ' '), {"larger than"});
  // Structurally valid, semantically wrong: the field is named.
  std::string y = written_by_opencv(test::make_sl_calibration());
  const auto at = y.find("units:");
  y.replace(at, y.find('\n', at) - at, "units: furlongs");
  expect_parse_error(y, {"units", "furlongs"});
}

TEST(SlCalibrationParseTest, FileLimitsAreCheckedBeforeReading) {
  const auto dir = test::make_temp_dir("sl_parse_file");
  {
    std::ofstream out(dir / "big.yml", std::ios::binary);
    out << std::string((1 << 20) + 1, 'a');
  }
  try {
    read_sl_calibration(dir / "big.yml");
    ADD_FAILURE() << "no InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("big.yml"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("larger than"), std::string::npos);
  }
}

// Seeded random mutations of valid YAML and XML (byte flips, insertions, truncations): every one
// either parses or is an InputError, never another exception or a crash.
TEST(SlCalibrationParseTest, MutatedFilesParseOrAreInputErrors) {
  const SlCalibration c = test::make_sl_calibration();
  const std::string yaml = written_by_opencv(c);
  const auto kamino = test::make_temp_dir("sl_parse_mut") / "k.xml";
  write_sl_calibration_kamino(kamino, c);
  std::ifstream in(kamino);
  const std::string xml(std::istreambuf_iterator<char>(in), {});
  std::mt19937_64 rng(42);
  std::string alphabet = "<>/\"=:[],.-+ \n\t0123456789eabcdrowsl_!%\x01";
  alphabet += '\0';
  alphabet += '\xff';
  int parsed = 0, errors = 0;
  for (int it = 0; it < 3000; ++it) {
    std::string t = it % 2 ? yaml : xml;
    const int edits = 1 + static_cast<int>(rng() % 4);
    for (int e = 0; e < edits && !t.empty(); ++e) {
      const std::size_t pos = rng() % t.size();
      const char ch = alphabet[rng() % alphabet.size()];
      switch (rng() % 4) {
        case 0:
          t[pos] = ch;
          break;
        case 1:
          t.insert(pos, 1, ch);
          break;
        case 2:
          t.erase(pos, 1 + rng() % 8);
          break;
        default:
          t.resize(pos);
          break;
      }
    }
    try {
      parse_sl_calibration(t, "mutated");
      ++parsed;
    } catch (const InputError&) {
      ++errors;
    }
  }
  std::printf("mutations: %d parsed, %d InputErrors\n", parsed, errors);
  EXPECT_GT(errors, 1000);
}

}  // namespace
}  // namespace scanclean

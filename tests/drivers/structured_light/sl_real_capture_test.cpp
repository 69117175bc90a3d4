// The real kamino410 Gray-code capture (../shared/data/structured_light_kamino410, PROVENANCE.md
// §8): decode with both decoders, triangulate, and measure the flatness of the printed
// checkerboard (a flat target) before and after the robust filter. Skipped without ../shared.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "scanclean/drivers/sl_board.h"
#include "scanclean/drivers/sl_calibrate.h"
#include "scanclean/drivers/sl_plane_fit.h"
#include "scanclean/drivers/sl_triangulate.h"
#include "scanclean/drivers/structured_light_source.h"
#include "support/data_paths.h"
#if defined(SCANCLEAN_SL_TEST_HAVE_FILTER)
#include "scanclean/filter/robust_filter.h"
#endif

namespace scanclean {
namespace {

const char* kCapture = "structured_light_kamino410/capture_0";

struct Real {
  SlResult result;
  std::vector<cv::Point2f> corners;  // inner chessboard corners in the white image
  cv::Mat board_mask;                // CV_8U: inside the outer ring of inner corners
};

const Real& real() {
  static const Real r = [] {
    Real x;
    x.result = process_sl_capture(test::shared_data_dir() / kCapture);
    const cv::Mat white = cv::imread(x.result.info.images[40].string(), cv::IMREAD_GRAYSCALE);
    // The calibration target: kamino410's sample command gives 9 x 7 inner corners.
    if (!cv::findChessboardCorners(white, cv::Size(9, 7), x.corners)) return x;
    std::vector<cv::Point> hull;
    std::vector<cv::Point> pts;
    for (const auto& c : x.corners) pts.emplace_back(cvRound(c.x), cvRound(c.y));
    cv::convexHull(pts, hull);
    x.board_mask = cv::Mat::zeros(white.size(), CV_8U);
    cv::fillConvexPoly(x.board_mask, hull, cv::Scalar(255));
    return x;
  }();
  return r;
}

TEST(SlRealCaptureTest, DecodesAndTriangulates) {
  SCANCLEAN_REQUIRE_SHARED(kCapture);
  const SlResult& r = real().result;
  const std::size_t pixels = r.decoded.status.size();
  std::printf(
      "kamino410 capture_0: %dx%d, valid %zu (%.1f %%), lit %.1f %%, decode %.1f ms "
      "(fast), Gray-code step %d (estimated: median reprojection %.2f px), points %zu, "
      "rejected by the epipolar check %zu, mean reprojection %.2f px\n",
      r.decoded.status.width, r.decoded.status.height, r.decoded.valid,
      100.0 * r.decoded.valid / pixels, 100.0 * r.decoded.lit / pixels, r.decoded.seconds * 1e3,
      r.calibration.graycode_step, r.step_median_reprojection_px, r.triangulation.points,
      r.triangulation.rejected_reprojection, r.triangulation.mean_reprojection_px);
  EXPECT_EQ(r.info.layout, "kamino410");
  EXPECT_EQ(r.info.graycode.projector_width, 1024);  // from ../graycode_pattern/pattern_00.png
  EXPECT_EQ(r.info.graycode.projector_height, 768);
  EXPECT_TRUE(r.calibration.unit_assumed);
  // The shipped calibration_result.xml only fits the shipped patterns with projector pixel
  // = 2 x decoded pixel: at step 1 column and row disagree by hundreds of pixels.
  EXPECT_EQ(r.calibration.graycode_step, 2);
  EXPECT_LT(r.step_median_reprojection_px, 5.0);
  EXPECT_GT(r.decoded.valid, pixels / 3);
  EXPECT_GT(r.triangulation.points, r.decoded.valid * 9 / 10);
}

TEST(SlRealCaptureTest, FastDecoderEqualsOpenCV) {
  SCANCLEAN_REQUIRE_SHARED(kCapture);
  const SlCaptureInfo info = describe_sl_capture(test::shared_data_dir() / kCapture);
  const SlCapture capture = SlCapture::load(info);
  SlDecodeOptions o;
  o.white_threshold = 5;  // README of kamino410/procam-calibration
  o.black_threshold = 40;
  o.decoder = SlDecoder::kOpenCV;
  const SlDecoded ref = decode_graycode(capture, o);
  o.decoder = SlDecoder::kFast;
  o.threads = 1;
  const SlDecoded fast1 = decode_graycode(capture, o);
  o.threads = 0;
  const SlDecoded fast = decode_graycode(capture, o);
  std::printf(
      "decode 1280x1024 x 42: opencv getProjPixel %.0f ms, fast %.1f ms (1 thread), "
      "%.1f ms (all cores)\n",
      ref.seconds * 1e3, fast1.seconds * 1e3, fast.seconds * 1e3);
  EXPECT_EQ(ref.valid, fast.valid);
  std::size_t differ = 0;
  for (std::size_t i = 0; i < ref.status.size(); ++i)
    differ += ref.status.data[i] != fast.status.data[i] ||
              ref.column.data[i] != fast.column.data[i] || ref.row.data[i] != fast.row.data[i] ||
              ref.confidence.data[i] != fast.confidence.data[i];
  EXPECT_EQ(differ, 0u);
  EXPECT_EQ(fast1.column.data, fast.column.data);
}

TEST(SlRealCaptureTest, PatternsEqualTheShippedProjectorImages) {
  SCANCLEAN_REQUIRE_SHARED("structured_light_kamino410/graycode_pattern/pattern_41.png");
  const auto dir = test::make_temp_dir("sl_real_patterns");
  ASSERT_EQ(write_graycode_patterns(dir, 1024, 768), 42);
  int differ = 0;
  for (int k = 0; k < 42; ++k) {
    char ours[32], theirs[64];
    std::snprintf(ours, sizeof ours, "%03d.png", k);
    std::snprintf(theirs, sizeof theirs, "pattern_%02d.png", k);
    const cv::Mat a = cv::imread((dir / "patterns" / ours).string(), cv::IMREAD_UNCHANGED);
    const cv::Mat b = cv::imread(
        (test::shared_data_dir() / "structured_light_kamino410/graycode_pattern" / theirs).string(),
        cv::IMREAD_GRAYSCALE);
    ASSERT_EQ(a.size(), b.size()) << ours;
    differ += cv::countNonZero(a != b);
  }
  EXPECT_EQ(differ, 0);
}

// Board points (valid pixels inside the chessboard's inner-corner hull), metres.
std::vector<Eigen::Vector3d> board_points(const Real& x, cv::Rect roi, std::vector<float>* conf) {
  std::vector<Eigen::Vector3d> pts;
  const auto& P = *x.result.frame.points;
  for (int v = roi.y; v < roi.y + roi.height; ++v)
    for (int u = roi.x; u < roi.x + roi.width; ++u) {
      if (!x.board_mask.at<std::uint8_t>(v, u) || !P(u, v).allFinite()) continue;
      pts.push_back(P(u, v).cast<double>());
      if (conf) conf->push_back((*x.result.frame.confidence)(u, v));
    }
  return pts;
}

double rms_to(const PlaneFit& f, const std::vector<Eigen::Vector3d>& pts) {
  double s = 0;
  for (const auto& p : pts) s += f.distance(p) * f.distance(p);
  return std::sqrt(s / static_cast<double>(pts.size()));
}

TEST(SlRealCaptureTest, BoardIsFlatAndSquaresAre75mm) {
  SCANCLEAN_REQUIRE_SHARED(kCapture);
  const Real& x = real();
  ASSERT_EQ(x.corners.size(), 63u) << "chessboard not found in graycode_40.png";
  const cv::Rect all(0, 0, x.board_mask.cols, x.board_mask.rows);
  const auto pts = board_points(x, all, nullptr);
  const int board_pixels = cv::countNonZero(x.board_mask);
  PlaneFitOptions po;
  // 10 mm band: about one depth-quantization stair (see RobustFilterFlattensTheBoard).
  po.inlier_threshold = 0.010;
  const PlaneFit plane = fit_plane_robust(pts, po);
  std::printf(
      "board: %d pixels, %zu points (%.1f %%: black squares are below the black "
      "threshold), plane inliers (10 mm) %.2f %%, RMS inliers %.3f mm, RMS all %.3f mm\n",
      board_pixels, pts.size(), 100.0 * pts.size() / board_pixels,
      100.0 * plane.inliers.size() / pts.size(), plane.rms * 1e3, rms_to(plane, pts) * 1e3);
  ASSERT_GT(pts.size(), 100000u);
  EXPECT_GT(plane.inliers.size(), pts.size() * 95 / 100);
  EXPECT_LT(plane.rms, 0.004);

  // Units: the inner corners' camera rays cut with the board plane must be 75 mm apart (the
  // square size of the calibration command) if the calibration's unit is the millimetre.
  const Intrinsics& K = x.result.calibration.camera;
  const cv::Mat Km = (cv::Mat_<double>(3, 3) << K.fx, 0, K.cx, 0, K.fy, K.cy, 0, 0, 1);
  const cv::Mat D =
      (cv::Mat_<double>(1, 5) << K.dist[0], K.dist[1], K.dist[2], K.dist[3], K.dist[4]);
  std::vector<cv::Point2d> in(x.corners.begin(), x.corners.end()), norm;
  cv::undistortPoints(in, norm, Km, D);
  std::vector<Eigen::Vector3d> c3;
  for (const auto& n : norm) {
    const Eigen::Vector3d ray(n.x, n.y, 1.0);
    c3.push_back(ray * (-plane.offset / plane.normal.dot(ray)));
  }
  double sum = 0;
  int count = 0;
  for (int row = 0; row < 7; ++row)
    for (int col = 0; col + 1 < 9; ++col) {
      sum += (c3[static_cast<std::size_t>(row * 9 + col + 1)] -
              c3[static_cast<std::size_t>(row * 9 + col)])
                 .norm();
      ++count;
    }
  const double square_mm = sum / count * 1e3;
  std::printf(
      "chessboard square from the triangulated plane: %.2f mm (75 expected); board at "
      "%.3f m\n",
      square_mm, -plane.offset / plane.normal.z());
  EXPECT_NEAR(square_mm, 75.0, 3.0);
}

// Sub-stripe against integer decoding on the board of capture_0 (shipped calibration): the
// central 30 x 30 cm window's raw plane residual (measured 2.84 mm integer, 1.03 mm sub-stripe;
// most of what remains is the calibration's bow, see README) and the square size from the
// triangulated corners (local homographies of the decoded pixels).
TEST(SlRealCaptureTest, SubStripeFlattensTheBoardWindow) {
  SCANCLEAN_REQUIRE_SHARED(kCapture);
  const Real& x = real();
  const SlResult& r = x.result;
  SlDecodeOptions o;
  o.sub_stripe = false;
  const SlDecoded integer = decode_graycode(r.capture, o);
  SlCalibration c = r.calibration;
  const SlTriangulator tri(c);
  SlBoardMeasureOptions bo;
  const SlBoardCorners corners = find_sl_board_corners(r.capture, r.decoded, bo.board);
  ASSERT_TRUE(corners.found);
  EXPECT_EQ(corners.projector_found(), 63u);
  const SlBoardRegion region(corners, c, bo, kCapture);
  auto points = [](const RangeFrame& f) {
    std::vector<Eigen::Vector3d> p;
    for (const auto& q : f.points->data)
      if (q.allFinite()) p.push_back(q.cast<double>());
    return p;
  };
  const SlBoardMeasurement mi = measure_sl_board(points(tri.triangulate(integer)), region, bo, "");
  const SlBoardMeasurement ms = measure_sl_board(points(r.frame), region, bo, "");
  const SlSquareSize sq = measure_sl_squares(corners, c, bo.board);
  std::printf(
      "capture_0 board window (shipped calibration): raw RMS integer %.3f mm, sub-stripe %.3f "
      "mm; whole board %.3f / %.3f mm; squares %.3f mm (sd %.3f, %d); sub-stripe pixels %.1f %%\n",
      mi.window.rms_m * 1e3, ms.window.rms_m * 1e3, mi.board.rms_m * 1e3, ms.board.rms_m * 1e3,
      sq.mean_m * 1e3, sq.std_m * 1e3, sq.count,
      100.0 * r.decoded.sub_stripe_pixels / r.decoded.valid);
  EXPECT_GT(mi.window.points, 30000u);
  EXPECT_LT(ms.window.rms_m, 0.5 * mi.window.rms_m);
  EXPECT_LT(ms.board.rms_m, 0.7 * mi.board.rms_m);
  EXPECT_NEAR(sq.mean_m, 0.075, 0.0005);
  EXPECT_EQ(sq.count, 110);
}

// sl calibrate on capture_0..3 (Moreno-Taubin corners, OpenCV calibration): against the shipped
// calibration_result.xml (made from five captures) the camera agrees closely, the projector and
// the baseline less (README); the board decoded with the own calibration is flatter and its
// squares are true to size.
TEST(SlRealCaptureTest, CalibratesFromTheFourCaptures) {
  SCANCLEAN_REQUIRE_SHARED("structured_light_kamino410/capture_3/graycode_41.png");
  std::vector<SlCapture> caps;
  std::vector<SlDecoded> dec;
  for (int k = 0; k < 4; ++k) {
    const auto folder =
        test::shared_data_dir() / ("structured_light_kamino410/capture_" + std::to_string(k));
    caps.push_back(SlCapture::load(describe_sl_capture(folder)));
    dec.push_back(decode_graycode(caps.back()));
  }
  const SlCalibrateResult res = calibrate_sl(caps, dec, {});
  const SlCalibration& own = res.calibration;
  const SlCalibration& shipped = real().result.calibration;
  std::printf(
      "own calibration: RMS camera %.3f px, projector %.3f px, stereo %.3f px; camera fx %.1f "
      "(shipped %.1f); projector fx %.1f (shipped / 2: %.1f); |T| %.1f mm (shipped %.1f)\n",
      res.camera_rms_px, res.projector_rms_px, res.stereo_rms_px, own.camera.fx, shipped.camera.fx,
      own.projector.fx, shipped.projector.fx / 2, own.T.norm() * 1e3, shipped.T.norm());
  for (const auto& v : res.views) EXPECT_TRUE(v.used) << v.name << ": " << v.reason;
  EXPECT_LT(res.camera_rms_px, 0.5);
  EXPECT_LT(res.projector_rms_px, 0.4);
  EXPECT_NEAR(own.camera.fx, shipped.camera.fx, 0.005 * shipped.camera.fx);
  EXPECT_NEAR(own.camera.fy, shipped.camera.fy, 0.005 * shipped.camera.fy);
  EXPECT_NEAR(own.projector.fx, shipped.projector.fx / 2, 0.06 * shipped.projector.fx / 2);
  EXPECT_NEAR(own.T.norm(), shipped.T.norm() * shipped.unit_m, 0.08 * shipped.T.norm() * 1e-3);

  // capture_0 with the own calibration: squares and the board's flatness.
  SlBoardMeasureOptions bo;
  const SlBoardCorners corners = find_sl_board_corners(caps[0], dec[0], bo.board);
  const SlSquareSize sq = measure_sl_squares(corners, own, bo.board);
  const SlBoardRegion region(corners, own, bo, "capture_0");
  const RangeFrame f = SlTriangulator(own).triangulate(dec[0]);
  std::vector<Eigen::Vector3d> pts;
  for (const auto& q : f.points->data)
    if (q.allFinite()) pts.push_back(q.cast<double>());
  const SlBoardMeasurement m = measure_sl_board(pts, region, bo, "capture_0");
  std::printf(
      "capture_0, own calibration, sub-stripe: board RMS %.3f mm, window %.3f mm, "
      "squares %.3f mm\n",
      m.board.rms_m * 1e3, m.window.rms_m * 1e3, sq.mean_m * 1e3);
  EXPECT_NEAR(sq.mean_m, 0.075, 0.0002);
  EXPECT_LT(m.board.rms_m, 0.0012);  // shipped calibration, integer decode: 3.18 mm
}

#if defined(SCANCLEAN_SL_TEST_HAVE_FILTER)
TEST(SlRealCaptureTest, RobustFilterFlattensTheBoard) {
  SCANCLEAN_REQUIRE_SHARED(kCapture);
  const Real& x = real();
  ASSERT_EQ(x.corners.size(), 63u);
  // A 240 x 240 pixel window at the board centre keeps the test fast (also under ASan).
  cv::Point2f centre(0, 0);
  for (const auto& c : x.corners) centre += c;
  centre *= 1.0f / static_cast<float>(x.corners.size());
  const cv::Rect roi(cvRound(centre.x) - 120, cvRound(centre.y) - 120, 240, 240);
  PointCloud cloud;
  cloud.positions = board_points(x, roi, &cloud.confidences);
  ASSERT_GT(cloud.size(), 10000u);
  PlaneFitOptions po;
  po.inlier_threshold = 0.010;
  const PlaneFit before = fit_plane_robust(cloud.positions, po);
  const double rms_before = rms_to(before, cloud.positions);

  // The noise here is mostly the depth quantization of integer projector rows (the baseline is
  // vertical): one decoded row is step * z^2 / (f_p |T|), about 11 mm at 3.65 m, a staircase
  // of about 1.8 camera pixels per step. The automatic h (from the point spacing, 5.7 mm here)
  // lies inside one stair; a kernel of two steps spans the staircase.
  const SlCalibration& c = x.result.calibration;
  const double z = -before.offset / before.normal.z();
  const double stair = c.graycode_step * z * z / (c.projector.fy * c.T.norm() * c.unit_m);
  FilterOptions fo;
  fo.scale = ScaleMode::kFixed;
  fo.h = 2.0 * stair;
  fo.merge_eps = 0;  // keep every point: the same points before and after
  const FilterResult filtered = robust_filter(cloud, fo);
  ASSERT_GT(filtered.cloud.size(), cloud.size() * 9 / 10);
  const PlaneFit after = fit_plane_robust(filtered.cloud.positions, po);
  const double rms_after = rms_to(after, filtered.cloud.positions);
  std::printf(
      "board window: %zu points, depth stair %.2f mm, RMS to the plane %.3f mm before, "
      "%.3f mm after the robust filter (%zu points, h %.2f mm)\n",
      cloud.size(), stair * 1e3, rms_before * 1e3, rms_after * 1e3, filtered.cloud.size(),
      filtered.stats.h * 1e3);
  EXPECT_LT(rms_after, 0.5 * rms_before);
}
#endif

}  // namespace
}  // namespace scanclean

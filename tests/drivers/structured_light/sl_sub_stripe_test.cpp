// Sub-stripe decoding and camera-projector calibration on synthetic captures rendered through a
// known calibration (sl_fixtures.h): the sub-stripe projector coordinates are far closer to the
// truth than the integer ones and the plane they triangulate is far flatter; calibrate_sl
// recovers the intrinsics and the pose from six chessboard poses.

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "scanclean/core/errors.h"
#include "scanclean/drivers/sl_board.h"
#include "scanclean/drivers/sl_calibrate.h"
#include "scanclean/drivers/sl_decode.h"
#include "scanclean/drivers/sl_triangulate.h"
#include "sl_fixtures.h"

namespace scanclean {
namespace {

SlCaptureInfo info_for(const SlCalibration& c) {
  SlCaptureInfo info;
  info.layout = "scanclean";
  info.graycode = graycode_layout(c.projector.width, c.projector.height);
  info.white_index = info.graycode.pattern_count();
  info.black_index = info.white_index + 1;
  return info;
}

struct Errors {
  double coord_rms = 0;  // projector pixels, both axes
  double plane_rms_mm = 0;
  std::size_t n = 0;
};

Errors errors_of(const SlDecoded& d, const test::SlRendered& r, const SlCalibration& c,
                 const test::SlScene& scene, bool sub) {
  const RangeFrame f = SlTriangulator(c).triangulate(d);
  Errors e;
  double sc = 0, sp = 0;
  for (int v = 0; v < c.camera.height; ++v)
    for (int u = 0; u < c.camera.width; ++u) {
      const std::size_t i = static_cast<std::size_t>(v) * c.camera.width + u;
      if (r.truth.surface(u, v) != 0 || !r.truth.lit(u, v) || d.column.data[i] < 0) continue;
      const Eigen::Vector3f& p = (*f.points)(u, v);
      if (!p.allFinite()) continue;
      const Eigen::Vector2d t = r.truth.proj(u, v);
      const double pc = sub ? d.column_f.data[i] : d.column.data[i];
      const double pr = sub ? d.row_f.data[i] : d.row.data[i];
      sc += (pc - t.x()) * (pc - t.x()) + (pr - t.y()) * (pr - t.y());
      const double dist = test::sl_surface_distance(scene, 0, p.cast<double>() * 1e3);
      sp += dist * dist;
      ++e.n;
    }
  e.coord_rms = std::sqrt(sc / (2.0 * e.n));
  e.plane_rms_mm = std::sqrt(sp / e.n);
  return e;
}

TEST(SlSubStripeTest, FarCloserToTheTruthThanTheIntegerDecode) {
  const SlCalibration c = test::make_sl_calibration();
  test::SlScene scene;
  scene.with_sphere = false;
  scene.supersample = 4;
  const test::SlRendered r = test::render_sl_capture(c, scene);
  const SlCapture cap = SlCapture::from_images(info_for(c), r.images);
  SlDecodeOptions o;
  o.sub_stripe = false;
  const SlDecoded integer = decode_graycode(cap, o);
  o.sub_stripe = true;
  const SlDecoded sub = decode_graycode(cap, o);
  // The sub-stripe pass keeps the integer decode and its validity.
  EXPECT_EQ(sub.column.data, integer.column.data);
  EXPECT_EQ(sub.valid, integer.valid);
  EXPECT_GT(sub.sub_stripe_pixels, sub.valid * 8 / 10);
  const Errors ei = errors_of(integer, r, c, scene, false);
  const Errors es = errors_of(sub, r, c, scene, true);
  std::printf(
      "synthetic plane: %zu pixels; projector coordinate RMS error integer %.3f px, sub-stripe "
      "%.3f px; plane residual RMS integer %.4f mm, sub-stripe %.4f mm\n",
      es.n, ei.coord_rms, es.coord_rms, ei.plane_rms_mm, es.plane_rms_mm);
  ASSERT_GT(es.n, 100000u);
  // Integer decode: uniform rounding error, about 1 / sqrt(12) = 0.29 px.
  EXPECT_GT(ei.coord_rms, 0.2);
  EXPECT_LT(es.coord_rms, ei.coord_rms / 3);
  EXPECT_LT(es.plane_rms_mm, ei.plane_rms_mm / 3);
}

TEST(SlSubStripeTest, LowConfidenceMarksTheLessAccurateCoordinates) {
  // A chessboard (printed edges: mixed pixels) at the fixture's full resolution.
  const SlCalibration c = test::make_sl_calibration();
  test::SlScene scene;
  scene.with_sphere = false;
  scene.chessboard = true;
  scene.square_mm = 15;
  scene.supersample = 2;
  const test::SlRendered r = test::render_sl_capture(c, scene);
  const SlDecoded d = decode_graycode(SlCapture::from_images(info_for(c), r.images));
  std::vector<std::pair<float, double>> conf_err;  // confidence, coordinate error (px)
  for (int v = 0; v < c.camera.height; ++v)
    for (int u = 0; u < c.camera.width; ++u) {
      const std::size_t i = static_cast<std::size_t>(v) * c.camera.width + u;
      if (d.column.data[i] < 0 || r.truth.surface(u, v) != 0) continue;
      const Eigen::Vector2d t = r.truth.proj(u, v);
      conf_err.emplace_back(d.confidence.data[i],
                            std::hypot(d.column_f.data[i] - t.x(), d.row_f.data[i] - t.y()));
    }
  ASSERT_GT(conf_err.size(), 50000u);
  std::sort(conf_err.begin(), conf_err.end());
  // Mean error of the least confident tenth against the most confident half.
  const std::size_t n = conf_err.size();
  double low = 0, high = 0;
  for (std::size_t k = 0; k < n / 10; ++k) low += conf_err[k].second;
  for (std::size_t k = n / 2; k < n; ++k) high += conf_err[k].second;
  low /= static_cast<double>(n / 10);
  high /= static_cast<double>(n - n / 2);
  std::printf(
      "chessboard: mean coordinate error %.3f px (least confident 10 %%), %.3f px (most "
      "confident half)\n",
      low, high);
  EXPECT_GT(low, 2 * high);
}

TEST(SlSubStripeTest, OptionsAreValidated) {
  SlDecodeOptions o;
  o.sub_stripe_level = 9;
  EXPECT_THROW(validate(o), OptionError);
  o.sub_stripe_level = 0;
  o.sub_stripe_max_span_px = 1;
  EXPECT_THROW(validate(o), OptionError);
}

TEST(SlCalibrateTest, RecoversIntrinsicsAndPoseFromSixBoardPoses) {
  // The fixture's rig at half the resolution (fast): camera 320x240, projector 400x300.
  SlCalibration truth = test::make_sl_calibration();
  truth.camera.width = 320;
  truth.camera.height = 240;
  truth.camera.fx = truth.camera.fy = 500;
  truth.camera.cx = 159.5;
  truth.camera.cy = 119.5;
  truth.projector.width = 400;
  truth.projector.height = 300;
  truth.projector.fx = truth.projector.fy = 400;
  truth.projector.cx = 199.5;
  truth.projector.cy = 149.5;
  const std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> poses = {
      {{0.25, -0.1, -1.0}, {-5, 0, 400}}, {{-0.3, 0.15, -1.0}, {5, -5, 420}},
      {{0.1, 0.35, -1.0}, {0, 5, 390}},   {{-0.15, -0.3, -1.0}, {-8, 3, 410}},
      {{0.4, 0.2, -1.0}, {3, -4, 395}},   {{-0.1, 0.05, -1.0}, {0, 0, 430}},
  };
  std::vector<SlCapture> caps;
  std::vector<SlDecoded> dec;
  std::vector<test::SlScene> scenes;
  for (std::size_t k = 0; k < poses.size(); ++k) {
    test::SlScene s;
    s.with_sphere = false;
    s.chessboard = true;
    s.square_mm = 15;
    s.plane_normal = poses[k].first;
    s.plane_point = poses[k].second;
    s.board_x_dir = Eigen::Vector3d(1, 0.1 * static_cast<double>(k) - 0.15, 0);
    s.seed = 11 + k;
    const test::SlRendered r = test::render_sl_capture(truth, s);
    SlCaptureInfo info = info_for(truth);
    info.folder = "pose" + std::to_string(k);
    caps.push_back(SlCapture::from_images(info, r.images));
    dec.push_back(decode_graycode(caps.back()));
    scenes.push_back(s);
  }
  SlCalibrateOptions o;
  o.board.square_m = 0.015;
  const SlCalibrateResult res = calibrate_sl(caps, dec, o);
  const SlCalibration& c = res.calibration;
  std::printf(
      "synthetic calibration: RMS camera %.3f px, projector %.3f px, stereo %.3f px; camera fx "
      "%.1f fy %.1f (500) cx %.1f (159.5) cy %.1f (119.5); projector fx %.1f fy %.1f (400) cx "
      "%.1f (199.5) cy %.1f (149.5); |T| %.2f mm (250)\n",
      res.camera_rms_px, res.projector_rms_px, res.stereo_rms_px, c.camera.fx, c.camera.fy,
      c.camera.cx, c.camera.cy, c.projector.fx, c.projector.fy, c.projector.cx, c.projector.cy,
      c.T.norm() * 1e3);
  for (const auto& v : res.views) EXPECT_TRUE(v.used) << v.name << ": " << v.reason;
  EXPECT_LT(res.camera_rms_px, 0.3);
  EXPECT_LT(res.projector_rms_px, 0.3);
  EXPECT_NEAR(c.camera.fx, 500, 10);
  EXPECT_NEAR(c.camera.fy, 500, 10);
  EXPECT_NEAR(c.camera.cx, 159.5, 8);
  EXPECT_NEAR(c.camera.cy, 119.5, 8);
  EXPECT_NEAR(c.projector.fx, 400, 10);
  EXPECT_NEAR(c.projector.fy, 400, 10);
  EXPECT_NEAR(c.projector.cx, 199.5, 8);
  EXPECT_NEAR(c.projector.cy, 149.5, 8);
  const Eigen::Vector3d t_true = truth.T * truth.unit_m;
  EXPECT_NEAR(c.T.norm(), t_true.norm(), 0.02 * t_true.norm());
  // The baseline direction couples with the principal point: a few views of a 150 mm board fix
  // it to a degree or two.
  EXPECT_LT(std::acos(std::min(1.0, c.T.normalized().dot(t_true.normalized()))), 0.04);
  EXPECT_LT(Eigen::AngleAxisd(c.R * truth.R.transpose()).angle(), 0.01);
  EXPECT_EQ(c.projector.width, 400);
  EXPECT_EQ(c.graycode_step, 1);

  // The board measured with the recovered calibration: squares 15 mm.
  const SlBoardCorners bc = find_sl_board_corners(caps[0], dec[0], o.board);
  ASSERT_TRUE(bc.found);
  EXPECT_EQ(bc.projector_found(), 63u);
  const SlSquareSize sq = measure_sl_squares(bc, c, o.board);
  std::printf("synthetic board squares: %.3f mm (sd %.3f, %d)\n", sq.mean_m * 1e3, sq.std_m * 1e3,
              sq.count);
  EXPECT_NEAR(sq.mean_m, 0.015, 0.0002);
}

TEST(SlCalibrateTest, TooFewViewsAreNamed) {
  const SlCalibration truth = test::make_sl_calibration();
  test::SlScene s;
  s.with_sphere = false;  // no chessboard: the smooth texture
  s.supersample = 1;
  const test::SlRendered r = test::render_sl_capture(truth, s);
  SlCaptureInfo info = info_for(truth);
  info.folder = "plain_wall";
  std::vector<SlCapture> caps(3, SlCapture::from_images(info, r.images));
  std::vector<SlDecoded> dec(3, decode_graycode(caps[0]));
  try {
    calibrate_sl(caps, dec, {});
    ADD_FAILURE() << "no InputError";
  } catch (const InputError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("plain_wall"), std::string::npos) << m;
    EXPECT_NE(m.find("chessboard not found"), std::string::npos) << m;
  }
}

}  // namespace
}  // namespace scanclean

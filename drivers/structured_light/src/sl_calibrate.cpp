#include "scanclean/drivers/sl_calibrate.h"

#include <cmath>
#include <opencv2/calib3d.hpp>

#include "scanclean/core/errors.h"

namespace scanclean {
namespace {

Intrinsics to_intrinsics(const cv::Mat& K, const cv::Mat& D, int w, int h) {
  Intrinsics k;
  k.fx = K.at<double>(0, 0);
  k.fy = K.at<double>(1, 1);
  k.cx = K.at<double>(0, 2);
  k.cy = K.at<double>(1, 2);
  for (int i = 0; i < 5; ++i) k.dist[static_cast<std::size_t>(i)] = D.at<double>(i);
  k.width = w;
  k.height = h;
  k.source = "calibration";
  return k;
}

double view_rms(const std::vector<cv::Point3f>& obj, const std::vector<cv::Point2f>& img,
                const cv::Mat& rvec, const cv::Mat& tvec, const cv::Mat& K, const cv::Mat& D) {
  std::vector<cv::Point2f> proj;
  cv::projectPoints(obj, rvec, tvec, K, D, proj);
  double s = 0;
  for (std::size_t i = 0; i < img.size(); ++i) {
    const cv::Point2f d = proj[i] - img[i];
    s += d.dot(d);
  }
  return std::sqrt(s / static_cast<double>(img.size()));
}

}  // namespace

void validate(const SlCalibrateOptions& o) {
  validate(o.board);
  validate(o.corners);
  if (o.min_views < 3 || o.min_views > 1000)
    throw OptionError("min views: " + std::to_string(o.min_views) + ", expected 3..1000");
  if (o.min_projector_corners < 0) throw OptionError("min projector corners: expected >= 0");
}

SlCalibrateResult calibrate_sl(const std::vector<SlCapture>& captures,
                               const std::vector<SlDecoded>& decoded, const SlCalibrateOptions& o) {
  validate(o);
  if (captures.size() != decoded.size())
    throw OptionError("calibrate_sl: captures and decoded differ in number");
  const int n_corners = o.board.cols * o.board.rows;
  const int need = o.min_projector_corners > 0 ? o.min_projector_corners : n_corners;
  std::vector<cv::Point3f> grid;
  for (int r = 0; r < o.board.rows; ++r)
    for (int c = 0; c < o.board.cols; ++c)
      grid.emplace_back(static_cast<float>(c * o.board.square_m),
                        static_cast<float>(r * o.board.square_m), 0.0f);
  SlCalibrateResult res;
  std::vector<std::vector<cv::Point3f>> obj;
  std::vector<std::vector<cv::Point2f>> cam, proj;
  std::vector<std::size_t> used;
  cv::Size cam_size, proj_size;
  std::string why;
  for (std::size_t v = 0; v < captures.size(); ++v) {
    const auto& info = captures[v].info();
    SlCalibrationView view;
    view.name = info.folder.string();
    if (v == 0) {
      cam_size = cv::Size(captures[v].width(), captures[v].height());
      proj_size = cv::Size(info.graycode.projector_width, info.graycode.projector_height);
    } else if (cam_size != cv::Size(captures[v].width(), captures[v].height()) ||
               proj_size !=
                   cv::Size(info.graycode.projector_width, info.graycode.projector_height)) {
      throw InputError(view.name, "", "camera or projector size differs from the first capture");
    }
    const SlBoardCorners bc = find_sl_board_corners(captures[v], decoded[v], o.board, o.corners);
    std::vector<cv::Point3f> ob;
    std::vector<cv::Point2f> cp, pp;
    if (bc.found)
      for (std::size_t k = 0; k < bc.camera.size(); ++k) {
        if (!bc.projector[k].allFinite()) continue;
        ob.push_back(grid[k]);
        cp.emplace_back(static_cast<float>(bc.camera[k].x()), static_cast<float>(bc.camera[k].y()));
        pp.emplace_back(static_cast<float>(bc.projector[k].x()),
                        static_cast<float>(bc.projector[k].y()));
      }
    view.corners = static_cast<int>(ob.size());
    if (!bc.found)
      view.reason = "chessboard not found in the white image";
    else if (view.corners < need)
      view.reason = std::to_string(view.corners) + " of " + std::to_string(n_corners) +
                    " corners decoded in the projector";
    else {
      view.used = true;
      obj.push_back(ob);
      cam.push_back(cp);
      proj.push_back(pp);
      used.push_back(v);
    }
    if (!view.used) why += "\n  " + view.name + ": " + view.reason;
    res.views.push_back(view);
  }
  if (static_cast<int>(obj.size()) < o.min_views)
    throw InputError(captures.empty() ? std::string("calibration") : res.views.front().name, "",
                     "the board is usable in " + std::to_string(obj.size()) + " capture(s), " +
                         std::to_string(o.min_views) + " needed" + why);

  const cv::TermCriteria crit(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 200, 1e-10);
  cv::Mat Kc, Dc, Kp, Dp;
  std::vector<cv::Mat> rc, tc, rp, tp;
  int flags = 0;
  if (!o.estimate_k3) flags |= cv::CALIB_FIX_K3;
  if (o.zero_tangential) flags |= cv::CALIB_ZERO_TANGENT_DIST;
  res.camera_rms_px = cv::calibrateCamera(obj, cam, cam_size, Kc, Dc, rc, tc, flags, crit);
  res.projector_rms_px = cv::calibrateCamera(obj, proj, proj_size, Kp, Dp, rp, tp, flags, crit);
  cv::Mat R, T, E, F;
  res.stereo_rms_px = cv::stereoCalibrate(obj, cam, proj, Kc, Dc, Kp, Dp, cam_size, R, T, E, F,
                                          cv::CALIB_FIX_INTRINSIC, crit);
  for (std::size_t k = 0; k < used.size(); ++k) {
    auto& view = res.views[used[k]];
    view.camera_rms_px = view_rms(obj[k], cam[k], rc[k], tc[k], Kc, Dc);
    view.projector_rms_px = view_rms(obj[k], proj[k], rp[k], tp[k], Kp, Dp);
  }
  SlCalibration& c = res.calibration;
  c.camera = to_intrinsics(Kc, Dc, cam_size.width, cam_size.height);
  c.projector = to_intrinsics(Kp, Dp, proj_size.width, proj_size.height);
  for (int i = 0; i < 3; ++i) {
    c.T(i) = T.at<double>(i);
    for (int j = 0; j < 3; ++j) c.R(i, j) = R.at<double>(i, j);
  }
  c.unit_m = 1.0;  // object points in metres
  c.rms = res.stereo_rms_px;
  c.graycode_step = 1;
  c.layout = "scanclean";
  return res;
}

}  // namespace scanclean

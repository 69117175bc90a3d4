#include "scanclean/drivers/sl_board.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "scanclean/core/atomic_file.h"
#include "scanclean/core/errors.h"
#include "scanclean/drivers/sl_plane_fit.h"
#include "scanclean/drivers/sl_triangulate.h"
#include "sl_capture_impl.h"
#include "sl_opencv.h"

namespace scanclean {
namespace {

using sl_detail::camera_matrix;
using sl_detail::dist_coeffs;

SlPlaneStats stats_of(const std::vector<Eigen::Vector3d>& pts, const PlaneFit& f) {
  SlPlaneStats s;
  s.points = pts.size();
  std::vector<double> a;
  a.reserve(pts.size());
  double sum = 0;
  for (const auto& p : pts) {
    const double d = f.distance(p);
    sum += d * d;
    a.push_back(std::abs(d));
  }
  s.rms_m = std::sqrt(sum / static_cast<double>(pts.size()));
  const std::size_t k = std::min(a.size() - 1, static_cast<std::size_t>(0.95 * a.size()));
  std::nth_element(a.begin(), a.begin() + static_cast<std::ptrdiff_t>(k), a.end());
  s.p95_m = a[k];
  s.inliers = static_cast<double>(f.inliers.size()) / static_cast<double>(pts.size());
  return s;
}

}  // namespace

void validate(const SlChessboard& b) {
  if (b.cols < 2 || b.cols > 100 || b.rows < 2 || b.rows > 100)
    throw OptionError("chessboard: " + std::to_string(b.cols) + "x" + std::to_string(b.rows) +
                      " inner corners, expected 2..100 each");
  if (!(b.square_m > 0) || !(b.square_m < 10))
    throw OptionError("square size: " + std::to_string(b.square_m) + " m, expected (0, 10) metres");
}

void parse_chessboard_size(const std::string& text, SlChessboard& board) {
  int c = 0, r = 0;
  char x = 0, extra = 0;
  if (std::sscanf(text.c_str(), "%d%c%d%c", &c, &x, &r, &extra) != 3 || (x != 'x' && x != 'X'))
    throw OptionError("--board: expected COLSxROWS inner corners (e.g. 9x7), got '" + text + "'");
  board.cols = c;
  board.rows = r;
  validate(board);
}

void validate(const SlCornerOptions& o) {
  if (o.window_radius_px < 3 || o.window_radius_px > 200)
    throw OptionError("corner window radius: " + std::to_string(o.window_radius_px) +
                      " px, expected 3..200");
  if (o.min_support < 8) throw OptionError("corner min support: expected >= 8 pixels");
  if (!(o.ransac_threshold > 0)) throw OptionError("corner RANSAC threshold: expected > 0");
}

void validate(const SlBoardMeasureOptions& o) {
  validate(o.board);
  if (!(o.window_m > 0) || !(o.window_m < 100))
    throw OptionError("board window: expected (0, 100) metres");
  if (!(o.band_m > 0) || !(o.band_m < 10)) throw OptionError("plane band: expected (0, 10) m");
}

std::size_t SlBoardCorners::projector_found() const {
  std::size_t n = 0;
  for (const auto& p : projector) n += p.allFinite();
  return n;
}

SlBoardCorners find_sl_board_corners(const SlCapture& capture, const SlDecoded& decoded,
                                     const SlChessboard& board, const SlCornerOptions& o) {
  validate(board);
  validate(o);
  const auto& cap = capture.impl();
  cv::Mat white = cap.images[static_cast<std::size_t>(cap.info.white_index)];
  if (white.depth() != CV_8U) white.convertTo(white, CV_8U, 1.0 / 256.0);
  SlBoardCorners out;
  std::vector<cv::Point2f> corners;
  const cv::Size size(board.cols, board.rows);
  if (!cv::findChessboardCorners(white, size, corners,
                                 cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE))
    return out;
  cv::cornerSubPix(white, corners, cv::Size(7, 7), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 50, 1e-3));
  out.found = true;
  const int w = decoded.column.width, h = decoded.column.height;
  const bool sub = decoded.column_f.size() == decoded.column.size();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (const auto& c : corners) {
    out.camera.emplace_back(c.x, c.y);
    std::vector<cv::Point2d> src, dst;
    const int cx = cvRound(c.x), cy = cvRound(c.y), r = o.window_radius_px;
    for (int v = std::max(0, cy - r); v <= std::min(h - 1, cy + r); ++v)
      for (int u = std::max(0, cx - r); u <= std::min(w - 1, cx + r); ++u) {
        const std::size_t i = static_cast<std::size_t>(v) * w + u;
        if (decoded.column.data[i] < 0) continue;
        double pc = decoded.column.data[i], pr = decoded.row.data[i];
        if (sub && std::isfinite(decoded.column_f.data[i]) &&
            std::isfinite(decoded.row_f.data[i])) {
          pc = decoded.column_f.data[i];
          pr = decoded.row_f.data[i];
        }
        // Coordinates relative to the corner keep the homography well conditioned.
        src.emplace_back(u - c.x, v - c.y);
        dst.emplace_back(pc, pr);
      }
    out.support.push_back(static_cast<int>(src.size()));
    Eigen::Vector2d p(nan, nan);
    if (static_cast<int>(src.size()) >= o.min_support) {
      cv::Mat mask;
      const cv::Mat H =
          cv::findHomography(src, dst, cv::RANSAC, o.ransac_threshold, mask, 2000, 0.999);
      if (!H.empty() && cv::countNonZero(mask) >= o.min_support) {
        // Refit on the inliers (least squares), then map the corner (the window origin).
        std::vector<cv::Point2d> s2, d2;
        for (std::size_t k = 0; k < src.size(); ++k)
          if (mask.at<std::uint8_t>(static_cast<int>(k))) {
            s2.push_back(src[k]);
            d2.push_back(dst[k]);
          }
        cv::Mat H2 = cv::findHomography(s2, d2, 0);
        if (H2.empty()) H2 = H;
        const double z = H2.at<double>(2, 2);
        if (std::abs(z) > 1e-12) p = {H2.at<double>(0, 2) / z, H2.at<double>(1, 2) / z};
      }
    }
    out.projector.push_back(p);
  }
  return out;
}

SlBoardRegion::SlBoardRegion(const SlBoardCorners& corners, const SlCalibration& calibration,
                             const SlBoardMeasureOptions& options, const std::string& where) {
  validate(options);
  const auto& b = options.board;
  if (!corners.found || corners.camera.size() != static_cast<std::size_t>(b.cols * b.rows))
    throw InputError(where, "white image",
                     "chessboard with " + std::to_string(b.cols) + "x" + std::to_string(b.rows) +
                         " inner corners not found (see --board)");
  std::vector<cv::Point2d> px, norm, obj;
  for (std::size_t k = 0; k < corners.camera.size(); ++k) {
    px.emplace_back(corners.camera[k].x(), corners.camera[k].y());
    obj.emplace_back(static_cast<double>(static_cast<int>(k) % b.cols) * b.square_m,
                     static_cast<double>(static_cast<int>(k) / b.cols) * b.square_m);
  }
  cv::undistortPoints(px, norm, camera_matrix(calibration.camera), dist_coeffs(calibration.camera));
  const cv::Mat H = cv::findHomography(norm, obj, 0);
  if (H.empty()) throw InputError(where, "chessboard", "degenerate corner grid");
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) H_(r, c) = H.at<double>(r, c);
  width_m_ = (b.cols - 1) * b.square_m;
  height_m_ = (b.rows - 1) * b.square_m;
  half_window_m_ = 0.5 * options.window_m;
}

Eigen::Vector2d SlBoardRegion::board_xy(const Eigen::Vector3d& p) const {
  const Eigen::Vector3d q = H_ * Eigen::Vector3d(p.x() / p.z(), p.y() / p.z(), 1.0);
  return {q.x() / q.z(), q.y() / q.z()};
}

bool SlBoardRegion::in_board(const Eigen::Vector3d& p) const {
  if (!(p.z() > 0)) return false;
  const Eigen::Vector2d b = board_xy(p);
  return b.x() >= 0 && b.y() >= 0 && b.x() <= width_m_ && b.y() <= height_m_;
}

bool SlBoardRegion::in_window(const Eigen::Vector3d& p) const {
  if (!(p.z() > 0)) return false;
  const Eigen::Vector2d b = board_xy(p);
  return std::abs(b.x() - 0.5 * width_m_) <= half_window_m_ &&
         std::abs(b.y() - 0.5 * height_m_) <= half_window_m_;
}

SlBoardMeasurement measure_sl_board(const std::vector<Eigen::Vector3d>& points,
                                    const SlBoardRegion& region,
                                    const SlBoardMeasureOptions& options,
                                    const std::string& where) {
  validate(options);
  std::vector<Eigen::Vector3d> board, window;
  for (const auto& p : points) {
    if (!p.allFinite() || !region.in_board(p)) continue;
    board.push_back(p);
    if (region.in_window(p)) window.push_back(p);
  }
  if (board.size() < 100 || window.size() < 100)
    throw InputError(where, "board",
                     "too few points on the board (" + std::to_string(board.size()) +
                         ") or in its window (" + std::to_string(window.size()) + ")");
  PlaneFitOptions po;
  po.inlier_threshold = options.band_m;
  SlBoardMeasurement m;
  const PlaneFit fb = fit_plane_robust(board, po);
  m.board = stats_of(board, fb);
  m.normal = fb.normal;
  m.offset = fb.offset;
  m.window = stats_of(window, fit_plane_robust(window, po));
  return m;
}

SlSquareSize measure_sl_squares(const SlBoardCorners& corners, const SlCalibration& calibration,
                                const SlChessboard& board) {
  SlSquareSize s;
  if (!corners.found || corners.camera.size() != static_cast<std::size_t>(board.cols * board.rows))
    return s;
  std::vector<std::optional<Eigen::Vector3d>> X(corners.camera.size());
  const double step = calibration.graycode_step;
  for (std::size_t k = 0; k < X.size(); ++k)
    if (corners.projector[k].allFinite())
      X[k] = triangulate_sl_point(calibration, corners.camera[k], step * corners.projector[k]);
  std::vector<double> d;
  for (int r = 0; r < board.rows; ++r)
    for (int c = 0; c < board.cols; ++c) {
      const auto& a = X[static_cast<std::size_t>(r * board.cols + c)];
      if (!a) continue;
      if (c + 1 < board.cols) {
        const auto& b = X[static_cast<std::size_t>(r * board.cols + c + 1)];
        if (b) d.push_back((*b - *a).norm());
      }
      if (r + 1 < board.rows) {
        const auto& b = X[static_cast<std::size_t>((r + 1) * board.cols + c)];
        if (b) d.push_back((*b - *a).norm());
      }
    }
  if (d.empty()) return s;
  double sum = 0, sq = 0;
  for (double v : d) sum += v;
  s.mean_m = sum / static_cast<double>(d.size());
  for (double v : d) sq += (v - s.mean_m) * (v - s.mean_m);
  s.std_m = std::sqrt(sq / static_cast<double>(d.size()));
  s.count = static_cast<int>(d.size());
  return s;
}

void write_sl_residual_map(const std::filesystem::path& file,
                           const std::vector<Eigen::Vector3d>& points,
                           const SlBoardMeasurement& plane, const SlBoardRegion& region,
                           const SlCalibration& calibration, double range_m) {
  const int w = calibration.camera.width, h = calibration.camera.height;
  std::vector<cv::Point3d> obj;
  std::vector<double> dist;
  for (const auto& p : points) {
    if (!p.allFinite() || !region.in_board(p)) continue;
    obj.emplace_back(p.x(), p.y(), p.z());
    dist.push_back(plane.normal.dot(p) + plane.offset);
  }
  cv::Mat value(h, w, CV_8U, cv::Scalar(0)), has(h, w, CV_8U, cv::Scalar(0));
  int x0 = w, y0 = h, x1 = -1, y1 = -1;
  if (!obj.empty()) {
    std::vector<cv::Point2d> px;
    cv::projectPoints(obj, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0),
                      camera_matrix(calibration.camera), dist_coeffs(calibration.camera), px);
    for (std::size_t k = 0; k < px.size(); ++k) {
      const int u = cvRound(px[k].x), v = cvRound(px[k].y);
      if (u < 0 || v < 0 || u >= w || v >= h) continue;
      const double t = std::clamp(0.5 + 0.5 * dist[k] / range_m, 0.0, 1.0);
      value.at<std::uint8_t>(v, u) = static_cast<std::uint8_t>(std::lround(t * 255));
      has.at<std::uint8_t>(v, u) = 255;
      x0 = std::min(x0, u);
      y0 = std::min(y0, v);
      x1 = std::max(x1, u);
      y1 = std::max(y1, v);
    }
  }
  cv::Mat colour;
  cv::applyColorMap(value, colour, cv::COLORMAP_JET);
  colour.setTo(cv::Scalar(0, 0, 0), has == 0);
  if (x1 >= x0 && y1 >= y0) {
    const int m = 10;
    const cv::Rect roi(cv::Point(std::max(0, x0 - m), std::max(0, y0 - m)),
                       cv::Point(std::min(w, x1 + m + 1), std::min(h, y1 + m + 1)));
    colour = colour(roi).clone();
  }
  // Colour bar with its range (mm) below the map.
  const int bar_h = 24;
  cv::Mat out(colour.rows + bar_h, std::max(colour.cols, 260), CV_8UC3, cv::Scalar(0, 0, 0));
  colour.copyTo(out(cv::Rect(0, 0, colour.cols, colour.rows)));
  cv::Mat ramp(1, 256, CV_8U);
  for (int i = 0; i < 256; ++i) ramp.at<std::uint8_t>(0, i) = static_cast<std::uint8_t>(i);
  cv::Mat ramp_c;
  cv::applyColorMap(ramp, ramp_c, cv::COLORMAP_JET);
  const int bw = std::min(out.cols - 120, 256);
  cv::resize(ramp_c, ramp_c, cv::Size(bw, 10), 0, 0, cv::INTER_NEAREST);
  ramp_c.copyTo(out(cv::Rect(60, colour.rows + 7, bw, 10)));
  char lo[32], hi[32];
  std::snprintf(lo, sizeof lo, "-%.1fmm", range_m * 1e3);
  std::snprintf(hi, sizeof hi, "+%.1fmm", range_m * 1e3);
  cv::putText(out, lo, cv::Point(2, colour.rows + 17), cv::FONT_HERSHEY_PLAIN, 0.8,
              cv::Scalar(255, 255, 255));
  cv::putText(out, hi, cv::Point(60 + bw + 4, colour.rows + 17), cv::FONT_HERSHEY_PLAIN, 0.8,
              cv::Scalar(255, 255, 255));
  std::vector<std::uint8_t> png;
  if (!cv::imencode(".png", out, png)) throw IoError(file.string() + ": cannot encode PNG");
  write_file_atomically(file, [&](std::ostream& os) {
    os.write(reinterpret_cast<const char*>(png.data()), static_cast<std::streamsize>(png.size()));
  });
}

}  // namespace scanclean

#include "scanclean/drivers/sl_triangulate.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <vector>

#include "scanclean/core/errors.h"
#include "sl_opencv.h"

namespace scanclean {
namespace {

using sl_detail::camera_matrix;
using sl_detail::dist_coeffs;

//! Normalised undistorted coordinates of the pixels (step u, step v) for u < w, v < h (row-major,
//! NaN where the iterative undistortion did not reproduce the pixel within 0.01 px).
std::vector<cv::Point2d> undistort_grid(const Intrinsics& K, int w, int h, int step) {
  std::vector<cv::Point2d> pix(static_cast<std::size_t>(w) * h);
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u)
      pix[static_cast<std::size_t>(v) * w + u] = {double(step) * u, double(step) * v};
  if (!K.has_distortion()) {
    std::vector<cv::Point2d> out(pix.size());
    for (std::size_t i = 0; i < pix.size(); ++i)
      out[i] = {(pix[i].x - K.cx) / K.fx, (pix[i].y - K.cy) / K.fy};
    return out;
  }
  const cv::Mat Km = camera_matrix(K), D = dist_coeffs(K);
  std::vector<cv::Point2d> norm;
  cv::undistortPoints(pix, norm, Km, D, cv::noArray(), cv::noArray(),
                      cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 100, 1e-6));
  // Check: distorting back must give the pixel (the iteration can fail for extreme distortion).
  std::vector<cv::Point3d> obj(norm.size());
  for (std::size_t i = 0; i < norm.size(); ++i) obj[i] = {norm[i].x, norm[i].y, 1.0};
  std::vector<cv::Point2d> back;
  cv::projectPoints(obj, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), Km, D, back);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (std::size_t i = 0; i < norm.size(); ++i)
    if (!(std::hypot(back[i].x - pix[i].x, back[i].y - pix[i].y) < 0.01)) norm[i] = {nan, nan};
  return norm;
}

}  // namespace

void validate(const SlTriangulationOptions& o) {
  if (!(o.max_reprojection_px > 0) || !std::isfinite(o.max_reprojection_px))
    throw OptionError("max reprojection error: " + std::to_string(o.max_reprojection_px) +
                      " px, expected > 0");
  if (!(o.min_depth_m >= 0)) throw OptionError("min depth: expected >= 0 m");
  if (!(o.max_depth_m >= 0) || (o.max_depth_m > 0 && o.max_depth_m <= o.min_depth_m))
    throw OptionError("max depth: " + std::to_string(o.max_depth_m) +
                      " m, expected 0 (no limit) or > min depth");
  if (!(o.depth_unit_m > 0) || o.depth_unit_m > 1)
    throw OptionError("depth unit: " + std::to_string(o.depth_unit_m) + " m, expected (0, 1]");
  if (!(o.calibration_unit_m >= 0) || o.calibration_unit_m > 1000)
    throw OptionError("calibration unit: " + std::to_string(o.calibration_unit_m) +
                      " m, expected 0 (the calibration's) or (0, 1000]");
}

struct SlTriangulator::Impl {
  SlCalibration calib;
  std::vector<cv::Point2d> camera_rays;  // (x, y) of the ray (x, y, 1)
  std::vector<cv::Point2d> projector;    // normalised undistorted projector pixel coordinates
  int grid_w = 0, grid_h = 0;            // decoded Gray-code grid (projector size / step)

  //! Bilinear interpolation of `projector` at continuous decoded coordinates (clamped to the
  //! grid; NaN if a corner is NaN).
  cv::Point2d projector_at(double c, double r) const {
    c = std::clamp(c, 0.0, static_cast<double>(grid_w - 1));
    r = std::clamp(r, 0.0, static_cast<double>(grid_h - 1));
    const int c0 = std::min(static_cast<int>(c), std::max(0, grid_w - 2));
    const int r0 = std::min(static_cast<int>(r), std::max(0, grid_h - 2));
    const int c1 = std::min(c0 + 1, grid_w - 1), r1 = std::min(r0 + 1, grid_h - 1);
    const double fc = c - c0, fr = r - r0;
    auto at = [&](int cc, int rr) {
      return projector[static_cast<std::size_t>(rr) * static_cast<std::size_t>(grid_w) +
                       static_cast<std::size_t>(cc)];
    };
    const cv::Point2d a = at(c0, r0), b = at(c1, r0), e = at(c0, r1), f = at(c1, r1);
    return (1 - fr) * ((1 - fc) * a + fc * b) + fr * ((1 - fc) * e + fc * f);
  }
};

SlTriangulator::SlTriangulator(const SlCalibration& calibration) : impl_(std::make_unique<Impl>()) {
  const std::string file = calibration.file.empty() ? "calibration" : calibration.file.string();
  if (calibration.camera.width <= 0 || calibration.camera.height <= 0)
    throw InputError(file, "", "camera image size unknown");
  if (calibration.projector.width <= 0 || calibration.projector.height <= 0)
    throw InputError(file, "", "projector size unknown");
  if (!calibration.camera.valid() || !calibration.projector.valid())
    throw InputError(file, "", "focal lengths must be positive");
  if (calibration.graycode_step < 1 || calibration.graycode_step > 64)
    throw InputError(file, "graycode_step", "expected 1..64");
  impl_->calib = calibration;
  const int step = calibration.graycode_step;
  impl_->grid_w = (calibration.projector.width - 1) / step + 1;
  impl_->grid_h = (calibration.projector.height - 1) / step + 1;
  impl_->camera_rays =
      undistort_grid(calibration.camera, calibration.camera.width, calibration.camera.height, 1);
  impl_->projector = undistort_grid(calibration.projector, impl_->grid_w, impl_->grid_h, step);
}

SlTriangulator::~SlTriangulator() = default;
SlTriangulator::SlTriangulator(SlTriangulator&&) noexcept = default;
SlTriangulator& SlTriangulator::operator=(SlTriangulator&&) noexcept = default;

const SlCalibration& SlTriangulator::calibration() const {
  return impl_->calib;
}

RangeFrame SlTriangulator::triangulate(const SlDecoded& d, const SlTriangulationOptions& o,
                                       SlTriangulationStats* stats_out) const {
  validate(o);
  const auto start = std::chrono::steady_clock::now();
  const SlCalibration& c = impl_->calib;
  const int w = c.camera.width, h = c.camera.height;
  if (d.column.width != w || d.column.height != h)
    throw InputError(c.file.empty() ? "calibration" : c.file.string(), "camera size",
                     "the calibration is for " + std::to_string(w) + "x" + std::to_string(h) +
                         " images, the capture has " + std::to_string(d.column.width) + "x" +
                         std::to_string(d.column.height));
  const double unit = o.calibration_unit_m > 0 ? o.calibration_unit_m : c.unit_m;
  const float nanf = std::numeric_limits<float>::quiet_NaN();
  RangeFrame f;
  f.K = c.camera;
  f.depth_unit_m = o.depth_unit_m;
  f.depth = Image<std::uint16_t>(w, h, 0);
  f.points = Image<Eigen::Vector3f>(w, h, Eigen::Vector3f(nanf, nanf, nanf));
  f.confidence = Image<float>(w, h, 0.0f);
  const Eigen::Matrix3d R = c.R;
  const Eigen::Vector3d T = c.T;
  const int pw = impl_->grid_w, ph = impl_->grid_h;
  const double pfx = c.projector.fx, pfy = c.projector.fy;
  const double max_res2 = o.max_reprojection_px * o.max_reprojection_px;
  const bool sub = d.column_f.size() == d.column.size() && d.row_f.size() == d.row.size();
  const double zmin = o.min_depth_m, zmax = o.max_depth_m > 0 ? o.max_depth_m : 1e300;

  // Per-row counters, summed in order afterwards (deterministic for any thread count).
  std::vector<std::size_t> n_dec(static_cast<std::size_t>(h)), n_pts(static_cast<std::size_t>(h)),
      n_rep(static_cast<std::size_t>(h)), n_dep(static_cast<std::size_t>(h));
  std::vector<double> sum_res(static_cast<std::size_t>(h));
  tbb::parallel_for(tbb::blocked_range<int>(0, h, 8), [&](const tbb::blocked_range<int>& r) {
    for (int v = r.begin(); v < r.end(); ++v) {
      const std::size_t vs = static_cast<std::size_t>(v);
      for (int u = 0; u < w; ++u) {
        const std::size_t i = vs * w + u;
        const int col = d.column.data[i], row = d.row.data[i];
        if (col < 0 || row < 0) continue;
        ++n_dec[vs];
        const cv::Point2d& cr = impl_->camera_rays[i];
        if (col >= pw || row >= ph || std::isnan(cr.x)) {
          ++n_dep[vs];
          continue;
        }
        cv::Point2d pp = impl_->projector[static_cast<std::size_t>(row) * pw + col];
        if (sub && !std::isnan(d.column_f.data[i]) && !std::isnan(d.row_f.data[i]))
          pp = impl_->projector_at(d.column_f.data[i], d.row_f.data[i]);
        if (std::isnan(pp.x)) {
          ++n_dep[vs];
          continue;
        }
        const Eigen::Vector3d rc(cr.x, cr.y, 1.0);
        const Eigen::Vector3d Rr = R * rc;
        const double a1 = Rr.x() - pp.x * Rr.z(), b1 = T.x() - pp.x * T.z();
        const double a2 = Rr.y() - pp.y * Rr.z(), b2 = T.y() - pp.y * T.z();
        const double den = a1 * a1 + a2 * a2;
        if (!(den > 1e-12)) {
          ++n_dep[vs];
          continue;
        }
        const double lambda = -(a1 * b1 + a2 * b2) / den;
        const Eigen::Vector3d Xp = lambda * Rr + T;
        const double z_m = lambda * unit;
        if (!(lambda > 0) || !(Xp.z() > 0) || z_m < zmin || z_m > zmax) {
          ++n_dep[vs];
          continue;
        }
        const double ex = (Xp.x() / Xp.z() - pp.x) * pfx, ey = (Xp.y() / Xp.z() - pp.y) * pfy;
        const double res2 = ex * ex + ey * ey;
        if (!(res2 <= max_res2)) {
          ++n_rep[vs];
          continue;
        }
        ++n_pts[vs];
        sum_res[vs] += std::sqrt(res2);
        const Eigen::Vector3d X = lambda * unit * rc;
        f.points->data[i] = X.cast<float>();
        f.confidence->data[i] = d.confidence.data[i];
        const double q = std::round(X.z() / o.depth_unit_m);
        f.depth.data[i] = q >= 1 && q <= 65535 ? static_cast<std::uint16_t>(q) : 0;
      }
    }
  });
  SlTriangulationStats s;
  double res = 0;
  for (int v = 0; v < h; ++v) {
    const std::size_t vs = static_cast<std::size_t>(v);
    s.decoded += n_dec[vs];
    s.points += n_pts[vs];
    s.rejected_reprojection += n_rep[vs];
    s.rejected_depth += n_dep[vs];
    res += sum_res[vs];
  }
  s.mean_reprojection_px = s.points ? res / static_cast<double>(s.points) : 0.0;
  s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (stats_out) *stats_out = s;
  return f;
}

std::optional<Eigen::Vector3d> triangulate_sl_point(const SlCalibration& c,
                                                    const Eigen::Vector2d& camera_px,
                                                    const Eigen::Vector2d& projector_px,
                                                    double* reprojection_px) {
  const cv::TermCriteria crit(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 100, 1e-9);
  std::vector<cv::Point2d> cam{{camera_px.x(), camera_px.y()}},
      proj{{projector_px.x(), projector_px.y()}};
  std::vector<cv::Point2d> cn, pn;
  cv::undistortPoints(cam, cn, camera_matrix(c.camera), dist_coeffs(c.camera), cv::noArray(),
                      cv::noArray(), crit);
  cv::undistortPoints(proj, pn, camera_matrix(c.projector), dist_coeffs(c.projector), cv::noArray(),
                      cv::noArray(), crit);
  const Eigen::Vector3d rc(cn[0].x, cn[0].y, 1.0);
  const Eigen::Vector3d Rr = c.R * rc;
  const double a1 = Rr.x() - pn[0].x * Rr.z(), b1 = c.T.x() - pn[0].x * c.T.z();
  const double a2 = Rr.y() - pn[0].y * Rr.z(), b2 = c.T.y() - pn[0].y * c.T.z();
  const double den = a1 * a1 + a2 * a2;
  if (!(den > 1e-12)) return std::nullopt;
  const double lambda = -(a1 * b1 + a2 * b2) / den;
  const Eigen::Vector3d Xp = lambda * Rr + c.T;
  if (!(lambda > 0) || !(Xp.z() > 0)) return std::nullopt;
  if (reprojection_px)
    *reprojection_px = std::hypot((Xp.x() / Xp.z() - pn[0].x) * c.projector.fx,
                                  (Xp.y() / Xp.z() - pn[0].y) * c.projector.fy);
  return Eigen::Vector3d(lambda * c.unit_m * rc);
}

double sl_median_reprojection_px(const SlDecoded& d, const SlCalibration& c, int step,
                                 int samples) {
  std::vector<cv::Point2d> cam, proj;
  std::size_t valid = 0;
  for (std::int32_t col : d.column.data) valid += col >= 0;
  if (valid == 0 || samples <= 0 || step < 1) return std::numeric_limits<double>::infinity();
  const std::size_t stride = std::max<std::size_t>(1, valid / static_cast<std::size_t>(samples));
  std::size_t k = 0;
  for (std::size_t i = 0; i < d.column.size(); ++i) {
    if (d.column.data[i] < 0) continue;
    if (k++ % stride != 0) continue;
    cam.emplace_back(static_cast<double>(i % d.column.width),
                     static_cast<double>(i / d.column.width));
    proj.emplace_back(double(step) * d.column.data[i], double(step) * d.row.data[i]);
  }
  const cv::TermCriteria crit(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 100, 1e-6);
  std::vector<cv::Point2d> cn, pn;
  cv::undistortPoints(cam, cn, camera_matrix(c.camera), dist_coeffs(c.camera), cv::noArray(),
                      cv::noArray(), crit);
  cv::undistortPoints(proj, pn, camera_matrix(c.projector), dist_coeffs(c.projector), cv::noArray(),
                      cv::noArray(), crit);
  std::vector<double> res;
  for (std::size_t i = 0; i < cn.size(); ++i) {
    const Eigen::Vector3d rc(cn[i].x, cn[i].y, 1.0);
    const Eigen::Vector3d Rr = c.R * rc;
    const double a1 = Rr.x() - pn[i].x * Rr.z(), b1 = c.T.x() - pn[i].x * c.T.z();
    const double a2 = Rr.y() - pn[i].y * Rr.z(), b2 = c.T.y() - pn[i].y * c.T.z();
    const double den = a1 * a1 + a2 * a2;
    double r = std::numeric_limits<double>::infinity();
    if (den > 1e-12) {
      const double lambda = -(a1 * b1 + a2 * b2) / den;
      const Eigen::Vector3d Xp = lambda * Rr + c.T;
      if (lambda > 0 && Xp.z() > 0)
        r = std::hypot((Xp.x() / Xp.z() - pn[i].x) * c.projector.fx,
                       (Xp.y() / Xp.z() - pn[i].y) * c.projector.fy);
    }
    res.push_back(r);
  }
  std::nth_element(res.begin(), res.begin() + static_cast<std::ptrdiff_t>(res.size() / 2),
                   res.end());
  return res[res.size() / 2];
}

int estimate_graycode_step(const SlDecoded& d, const SlCalibration& c, double* median_px) {
  int best = 1;
  double best_res = std::numeric_limits<double>::infinity();
  for (int step = 1; step <= 4; ++step) {
    const double r = sl_median_reprojection_px(d, c, step);
    if (r < best_res) {
      best_res = r;
      best = step;
    }
  }
  if (median_px) *median_px = best_res;
  return best;
}

}  // namespace scanclean

#include "sl_fixtures.h"

#include <Eigen/Geometry>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/structured_light.hpp>
#include <random>
#include <stdexcept>

namespace scanclean::test {
namespace {

Eigen::Vector2d distort(const Intrinsics& K, double x, double y) {
  const auto& d = K.dist;
  const double r2 = x * x + y * y;
  const double radial = 1 + d[0] * r2 + d[1] * r2 * r2 + d[4] * r2 * r2 * r2;
  const double xd = x * radial + 2 * d[2] * x * y + d[3] * (r2 + 2 * x * x);
  const double yd = y * radial + d[2] * (r2 + 2 * y * y) + 2 * d[3] * x * y;
  return {K.fx * xd + K.cx, K.fy * yd + K.cy};
}

struct Hit {
  int surface = -1;
  Eigen::Vector3d point;
  bool lit = false;
  Eigen::Vector2d proj{-1, -1};
};

// Smallest t > 0 of |o + t d - c| = r, or -1.
double ray_sphere(const Eigen::Vector3d& o, const Eigen::Vector3d& d, const Eigen::Vector3d& c,
                  double r) {
  const Eigen::Vector3d oc = o - c;
  const double a = d.dot(d), b = 2 * oc.dot(d), cc = oc.dot(oc) - r * r;
  const double disc = b * b - 4 * a * cc;
  if (disc < 0) return -1;
  const double s = std::sqrt(disc);
  const double t1 = (-b - s) / (2 * a), t2 = (-b + s) / (2 * a);
  if (t1 > 1e-9) return t1;
  if (t2 > 1e-9) return t2;
  return -1;
}

Hit cast(const SlCalibration& calib, const SlScene& s, const Eigen::Vector3d& ray) {
  Hit h;
  const Eigen::Vector3d n = s.plane_normal.normalized();
  double best = 1e300;
  const double denom = n.dot(ray);
  if (std::abs(denom) > 1e-12) {
    const double t = n.dot(s.plane_point) / denom;
    if (t > 0) {
      best = t;
      h.surface = 0;
    }
  }
  if (s.with_sphere) {
    const double t = ray_sphere(Eigen::Vector3d::Zero(), ray, s.sphere_centre, s.sphere_radius);
    if (t > 0 && t < best) {
      best = t;
      h.surface = 1;
    }
  }
  if (h.surface < 0) return h;
  h.point = best * ray;
  // Projector centre in the camera frame: X_p = R X_c + T = 0.
  const Eigen::Vector3d C = -calib.R.transpose() * calib.T;
  bool shadow = false;
  if (h.surface == 1) {
    shadow = (h.point - s.sphere_centre).dot(C - h.point) <= 0;  // faces away from the projector
  } else if (s.with_sphere) {
    const double t = ray_sphere(h.point, C - h.point, s.sphere_centre, s.sphere_radius);
    shadow = t > 0 && t < 1;
  }
  const Eigen::Vector3d Xp = calib.R * h.point + calib.T;
  if (Xp.z() <= 0) return h;
  h.proj = distort(calib.projector, Xp.x() / Xp.z(), Xp.y() / Xp.z());
  const double col = std::round(h.proj.x()), row = std::round(h.proj.y());
  h.lit = !shadow && col >= 0 && row >= 0 && col < calib.projector.width &&
          row < calib.projector.height;
  return h;
}

std::vector<Eigen::Vector3d> rays_for(const SlCalibration& calib,
                                      const std::vector<cv::Point2d>& pixels) {
  const Intrinsics& K = calib.camera;
  cv::Mat Km = (cv::Mat_<double>(3, 3) << K.fx, 0, K.cx, 0, K.fy, K.cy, 0, 0, 1);
  cv::Mat D = (cv::Mat_<double>(1, 5) << K.dist[0], K.dist[1], K.dist[2], K.dist[3], K.dist[4]);
  std::vector<cv::Point2d> norm;
  cv::undistortPoints(pixels, norm, Km, D, cv::noArray(), cv::noArray(),
                      cv::TermCriteria(cv::TermCriteria::COUNT, 10, 0));
  std::vector<Eigen::Vector3d> rays(norm.size());
  for (std::size_t i = 0; i < norm.size(); ++i) rays[i] = {norm[i].x, norm[i].y, 1.0};
  return rays;
}

void board_axes(const SlScene& s, Eigen::Vector3d& ex, Eigen::Vector3d& ey) {
  const Eigen::Vector3d n = s.plane_normal.normalized();
  ex = (s.board_x_dir - s.board_x_dir.dot(n) * n).normalized();
  ey = n.cross(ex).normalized();
}

double albedo_at(const SlScene& s, int surface, const Eigen::Vector3d& p) {
  if (s.chessboard && surface == 0) {
    Eigen::Vector3d ex, ey;
    board_axes(s, ex, ey);
    const double a = (p - s.plane_point).dot(ex) / s.square_mm;
    const double b = (p - s.plane_point).dot(ey) / s.square_mm;
    if (std::abs(a) > 0.5 * (s.board_cols + 1) || std::abs(b) > 0.5 * (s.board_rows + 1))
      return 0.6;
    // Inner corners at half-integer offsets when the count is odd, integer when even.
    const double oa = 0.5 * (s.board_cols - 1), ob = 0.5 * (s.board_rows - 1);
    const long i = static_cast<long>(std::floor(a + oa)), j = static_cast<long>(std::floor(b + ob));
    return ((i + j) % 2 == 0) ? 0.9 : 0.35;
  }
  return 0.55 + 0.3 * (0.5 + 0.5 * std::sin(p.x() / 7.0) * std::sin(p.y() / 9.0));
}

}  // namespace

std::vector<Eigen::Vector3d> sl_board_corners_mm(const SlScene& s) {
  Eigen::Vector3d ex, ey;
  board_axes(s, ex, ey);
  std::vector<Eigen::Vector3d> out;
  for (int r = 0; r < s.board_rows; ++r)
    for (int c = 0; c < s.board_cols; ++c)
      out.push_back(s.plane_point + (c - 0.5 * (s.board_cols - 1)) * s.square_mm * ex +
                    (r - 0.5 * (s.board_rows - 1)) * s.square_mm * ey);
  return out;
}

SlCalibration make_sl_calibration() {
  SlCalibration c;
  c.camera.fx = c.camera.fy = 1000;
  c.camera.cx = 319.5;
  c.camera.cy = 239.5;
  c.camera.dist = {-0.05, 0.02, 0.0005, -0.0003, 0.0};
  c.camera.width = 640;
  c.camera.height = 480;
  c.camera.source = "calibration";
  c.projector.fx = 800;
  c.projector.fy = 800;
  c.projector.cx = 399.5;
  c.projector.cy = 299.5;
  c.projector.dist = {0.03, -0.01, 0.0, 0.0, 0.0};
  c.projector.width = 800;
  c.projector.height = 600;
  c.projector.source = "calibration";
  // Projector centre at (250, 0, 0) mm, optical axis toward (0, 0, 400).
  const Eigen::Vector3d centre(250, 0, 0);
  const double phi = std::atan2(250.0, 400.0);
  c.R = Eigen::AngleAxisd(phi, Eigen::Vector3d::UnitY()).toRotationMatrix();
  // R^T e_z must point from the centre to the scene: (-sin phi, 0, cos phi).
  c.T = -c.R * centre;
  c.unit_m = 0.001;
  c.rms = 0.1;
  c.layout = "scanclean";
  return c;
}

SlRendered render_sl_capture(const SlCalibration& calib, const SlScene& scene) {
  const int w = calib.camera.width, h = calib.camera.height, ss = scene.supersample;
  const auto pattern =
      cv::structured_light::GrayCodePattern::create(calib.projector.width, calib.projector.height);
  std::vector<cv::Mat> patterns;
  pattern->generate(patterns);
  cv::Mat black, white;
  pattern->getImagesForShadowMasks(black, white);
  patterns.push_back(white);
  patterns.push_back(black);

  // Sub-samples: albedo and the projector pixel each one sees (-1 = unlit).
  std::vector<cv::Point2d> sub;
  sub.reserve(static_cast<std::size_t>(w) * h * ss * ss);
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u)
      for (int j = 0; j < ss; ++j)
        for (int i = 0; i < ss; ++i)
          sub.emplace_back(u - 0.5 + (i + 0.5) / ss, v - 0.5 + (j + 0.5) / ss);
  const std::vector<Eigen::Vector3d> rays = rays_for(calib, sub);
  std::vector<float> albedo(sub.size(), 0.0f);
  std::vector<int> pcol(sub.size(), -1), prow(sub.size(), -1);
  for (std::size_t i = 0; i < sub.size(); ++i) {
    const Hit hit = cast(calib, scene, rays[i]);
    if (hit.surface < 0) continue;
    albedo[i] = static_cast<float>(albedo_at(scene, hit.surface, hit.point));
    if (hit.lit) {
      pcol[i] = static_cast<int>(std::round(hit.proj.x()));
      prow[i] = static_cast<int>(std::round(hit.proj.y()));
    }
  }
  SlRendered out;
  std::mt19937_64 rng(scene.seed);  // seeded: the noise is reproducible
  std::normal_distribution<double> noise(0.0, scene.noise_sigma);
  const double inv = 1.0 / (ss * ss);
  for (const cv::Mat& pat : patterns) {
    cv::Mat img(h, w, CV_64F);
    std::size_t i = 0;
    for (int v = 0; v < h; ++v)
      for (int u = 0; u < w; ++u) {
        double acc = 0;
        for (int k = 0; k < ss * ss; ++k, ++i) {
          const double p = pcol[i] >= 0 ? pat.at<std::uint8_t>(prow[i], pcol[i]) / 255.0 : 0.0;
          acc += albedo[i] * (scene.ambient + scene.gain * p);
        }
        img.at<double>(v, u) = acc * inv;
      }
    if (scene.blur_sigma_px > 0) cv::GaussianBlur(img, img, cv::Size(0, 0), scene.blur_sigma_px);
    Image<std::uint8_t> im(w, h);
    for (int v = 0; v < h; ++v)
      for (int u = 0; u < w; ++u)
        im(u, v) = static_cast<std::uint8_t>(
            std::clamp(std::round(img.at<double>(v, u) + noise(rng)), 0.0, 255.0));
    out.images.push_back(std::move(im));
  }

  // Truth at the pixel centres.
  std::vector<cv::Point2d> centres;
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u) centres.emplace_back(u, v);
  const std::vector<Eigen::Vector3d> crays = rays_for(calib, centres);
  SlTruth& t = out.truth;
  t.surface = Image<std::int8_t>(w, h, -1);
  t.lit = Image<std::uint8_t>(w, h, 0);
  t.proj = Image<Eigen::Vector2d>(w, h, Eigen::Vector2d(-1, -1));
  t.edge_distance_px = Image<float>(w, h, 0.0f);
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u) {
      const Hit hit = cast(calib, scene, crays[static_cast<std::size_t>(v) * w + u]);
      t.surface(u, v) = static_cast<std::int8_t>(hit.surface);
      t.lit(u, v) = hit.lit;
      t.proj(u, v) = hit.proj;
    }
  for (int v = 1; v + 1 < h; ++v)
    for (int u = 1; u + 1 < w; ++u) {
      bool uniform = true;
      for (int dv = -1; dv <= 1; ++dv)
        for (int du = -1; du <= 1; ++du)
          uniform = uniform && t.surface(u + du, v + dv) == t.surface(u, v) &&
                    t.lit(u + du, v + dv) == t.lit(u, v);
      if (!uniform || !t.lit(u, v)) continue;
      const Eigen::Vector2d p = t.proj(u, v);
      const Eigen::Vector2d du = 0.5 * (t.proj(u + 1, v) - t.proj(u - 1, v));
      const Eigen::Vector2d dv = 0.5 * (t.proj(u, v + 1) - t.proj(u, v - 1));
      double dist = 1e9;
      for (int a = 0; a < 2; ++a) {
        const double to_boundary = 0.5 - std::abs(p[a] - std::round(p[a]));
        const double grad = std::hypot(du[a], dv[a]);
        dist = std::min(dist, to_boundary / std::max(grad, 1e-12));
      }
      t.edge_distance_px(u, v) = static_cast<float>(dist);
    }
  return out;
}

void write_sl_capture(const std::filesystem::path& folder, const SlCalibration& calib,
                      const std::vector<Image<std::uint8_t>>& images) {
  std::filesystem::create_directories(folder / "img");
  const int count = static_cast<int>(images.size()) - 2;
  nlohmann::json j;
  j["format"] = "scanclean-sl/1";
  j["projector"] = {{"width", calib.projector.width}, {"height", calib.projector.height}};
  j["pattern"] = "graycode";
  j["order"] = "opencv";
  j["count"] = count;
  j["white_index"] = count;
  j["black_index"] = count + 1;
  j["thresholds"] = {{"white", 5}, {"black", 40}};
  j["camera_serial"] = "synthetic-0";
  std::ofstream(folder / "capture.json") << j.dump(2);
  for (std::size_t k = 0; k < images.size(); ++k) {
    const auto& im = images[k];
    cv::Mat m(im.height, im.width, CV_8U, const_cast<std::uint8_t*>(im.data.data()));
    char name[32];
    std::snprintf(name, sizeof name, "%03zu.png", k);
    if (!cv::imwrite((folder / "img" / name).string(), m))
      throw std::runtime_error("cannot write test image");
  }
  write_sl_calibration(folder / "calib.yml", calib);
}

double sl_surface_distance(const SlScene& scene, int surface, const Eigen::Vector3d& p) {
  if (surface == 0) return scene.plane_normal.normalized().dot(p - scene.plane_point);
  return (p - scene.sphere_centre).norm() - scene.sphere_radius;
}

}  // namespace scanclean::test

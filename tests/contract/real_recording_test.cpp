// End-to-end on the bundled real PrimeSense recording recordings/oni/3dj_test.oni (12 frames,
// 640x480), read through the factory and OpenNI2: accumulating and cleaning all 12 frames gives
// a surface with clearly less temporal noise than a single frame.
//
// The scene is about 3.85 m away, where the PS1080 quantisation step is about 43 mm, so the
// temporal noise shows as pixels flipping between depth levels. Figures (central 160x120 crop,
// to keep the test fast under sanitizers), all printed:
//  - local plane-fit residual: each point's distance to the plane fitted to the points whose
//    pixels lie in its 5x5-pixel window (windows with a depth jump > 2 % skipped), for every raw
//    frame's points and for the cleaned points; RMS and median;
//  - deviation from the per-pixel 12-frame mean depth zbar (pixels valid in all frames): raw
//    z_i - zbar over all frames, cleaned q.z - zbar(project(q)) (bilinear). zbar is itself a
//    quantisation staircase at this range, so the smooth cleaned surface sits up to half a
//    step off it: its RMS (dominated by the raw level flips) falls, its median does not, and
//    only the RMS is asserted.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <vector>

#include "scanclean/drivers/make_range_source.h"
#include "scanclean/filter/robust_filter.h"
#include "scanclean/pipeline/accumulate.h"
#include "scanclean/pipeline/clean_window.h"
#include "scanclean/pipeline/frame_to_points.h"
#include "support/data_paths.h"

namespace scanclean {
namespace {

using namespace std::chrono_literals;

RangeFrame crop(const RangeFrame& f, int u0, int v0, int w, int h) {
  RangeFrame c;
  c.index = f.index;
  c.device_ts_us = f.device_ts_us;
  c.host_ts_ns = f.host_ts_ns;
  c.depth_unit_m = f.depth_unit_m;
  c.K = f.K;
  c.K.cx -= u0;
  c.K.cy -= v0;
  c.K.width = w;
  c.K.height = h;
  c.depth = Image<std::uint16_t>(w, h, 0);
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u) c.depth(u, v) = f.depth(u0 + u, v0 + v);
  return c;
}

// Distance of p to the least-squares plane of pts (PCA; smallest-eigenvalue direction).
double plane_residual(const Eigen::Vector3d& p, const std::vector<Eigen::Vector3d>& pts) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& q : pts) c += q;
  c /= static_cast<double>(pts.size());
  Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
  for (const auto& q : pts) C += (q - c) * (q - c).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(C);
  return std::abs(es.eigenvectors().col(0).dot(p - c));
}

// Residuals of points to the plane fitted to the points whose pixels lie in the 5x5 window
// around their own pixel (pixel = projection under K), skipping windows with fewer than 10
// points or a depth range above 2 % (depth jumps). The same window for raw and cleaned points.
std::vector<double> local_plane_residuals(const std::vector<Eigen::Vector3d>& points,
                                          const Intrinsics& K) {
  const int W = K.width, H = K.height;
  std::vector<std::vector<int>> cells(static_cast<std::size_t>(W) * H);
  std::vector<int> cell_of(points.size(), -1);
  for (std::size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector2d px = project_point(K, points[i]);
    const int u = static_cast<int>(std::lround(px.x())), v = static_cast<int>(std::lround(px.y()));
    if (u < 0 || v < 0 || u >= W || v >= H) continue;
    cell_of[i] = v * W + u;
    cells[cell_of[i]].push_back(static_cast<int>(i));
  }
  std::vector<double> res;
  std::vector<Eigen::Vector3d> nb;
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (cell_of[i] < 0) continue;
    const int u = cell_of[i] % W, v = cell_of[i] / W;
    if (u < 2 || v < 2 || u + 2 >= W || v + 2 >= H) continue;
    nb.clear();
    double lo = 1e9, hi = -1e9;
    for (int dv = -2; dv <= 2; ++dv)
      for (int du = -2; du <= 2; ++du)
        for (int j : cells[(v + dv) * W + (u + du)]) {
          nb.push_back(points[j]);
          lo = std::min(lo, points[j].z());
          hi = std::max(hi, points[j].z());
        }
    if (nb.size() < 10 || hi - lo > 0.02 * lo) continue;
    res.push_back(plane_residual(points[i], nb));
  }
  return res;
}

double rms(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x * x;
  return std::sqrt(s / v.size());
}

#ifdef SCANCLEAN_HAVE_OPENNI2
TEST(RealRecordingTest, AccumulatedCleanSurfaceHasLowerTemporalNoise) {
  auto src = make_range_source((test::recordings_dir() / "oni" / "3dj_test.oni").string());
  src->open();
  SourceInfo info = src->info();
  std::vector<RangeFrame> frames;
  RangeFrame f;
  ReadStatus s;
  while ((s = src->next(f, 5000ms)) == ReadStatus::kOk) frames.push_back(f);
  EXPECT_EQ(s, ReadStatus::kEndOfStream);
  ASSERT_EQ(frames.size(), 12u);
  for (const auto& fr : frames) {
    ASSERT_EQ(fr.depth.width, 640);
    ASSERT_EQ(fr.depth.height, 480);
  }
  const int W = 160, H = 120, u0 = (640 - W) / 2, v0 = (480 - H) / 2;
  std::vector<RangeFrame> cropped;
  for (const auto& fr : frames) cropped.push_back(crop(fr, u0, v0, W, H));
  info.K = cropped.front().K;

  const TemporalSpread t = temporal_depth_spread(cropped);
  ASSERT_GT(t.pixels_valid_in_all, static_cast<std::size_t>(W * H / 4));
  auto all_valid = [&](int u, int v) { return t.valid_count(u, v) == cropped.size(); };

  // Raw: each frame against the per-pixel mean (RMS and median |deviation| over all frames).
  double raw2 = 0, zsum = 0;
  std::size_t raw_n = 0;
  std::vector<double> raw_abs;
  for (const auto& fr : cropped)
    for (int v = 0; v < H; ++v)
      for (int u = 0; u < W; ++u) {
        if (!all_valid(u, v)) continue;
        const double d = fr.depth(u, v) * fr.depth_unit_m - t.mean_m(u, v);
        raw2 += d * d;
        raw_abs.push_back(std::abs(d));
        zsum += t.mean_m(u, v);
        ++raw_n;
      }
  const double raw_rms = std::sqrt(raw2 / raw_n);
  auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  };
  const double raw_med = median(raw_abs);

  // Cleaned: all 12 frames fused and filtered by the program's window path (clean_window with
  // the depth-frame preset, as replay and capture run it).
  WindowOptions wo;
  wo.filter.threads = 2;
  const WindowResult r = clean_window(cropped, info, wo);
  ASSERT_GT(r.cloud.size(), t.pixels_valid_in_all / 2);  // merged, yet covers the surface
  double clean2 = 0;
  std::size_t clean_n = 0;
  std::vector<double> clean_abs;
  const Intrinsics& K = info.K;
  for (const auto& q : r.cloud.positions) {
    const Eigen::Vector2d px = project_point(K, q);
    const int u = static_cast<int>(std::floor(px.x())), v = static_cast<int>(std::floor(px.y()));
    if (u < 0 || v < 0 || u + 1 >= W || v + 1 >= H) continue;
    if (!all_valid(u, v) || !all_valid(u + 1, v) || !all_valid(u, v + 1) ||
        !all_valid(u + 1, v + 1))
      continue;
    const double a = t.mean_m(u, v), b = t.mean_m(u + 1, v), c = t.mean_m(u, v + 1),
                 d = t.mean_m(u + 1, v + 1);
    const double lo = std::min({a, b, c, d}), hi = std::max({a, b, c, d});
    if (hi - lo > 0.02 * lo) continue;  // a depth jump: the mean is no surface there
    const double fx = px.x() - u, fy = px.y() - v;
    const double zbar = (1 - fy) * ((1 - fx) * a + fx * b) + fy * ((1 - fx) * c + fx * d);
    const double e = q.z() - zbar;
    clean2 += e * e;
    clean_abs.push_back(std::abs(e));
    ++clean_n;
  }
  ASSERT_GT(clean_n, r.cloud.size() / 2);
  const double clean_rms = std::sqrt(clean2 / clean_n);
  const double clean_med = median(clean_abs);
  // Local plane-fit residuals: every raw frame's points vs the cleaned points.
  std::vector<double> raw_res;
  FrameToPointsOptions po;
  po.edge_margin_px = 0;  // raw means raw: keep flying pixels out only through the jump test
  for (const auto& fr : cropped) {
    const std::vector<double> v = local_plane_residuals(frame_to_points(fr, info, po).positions, K);
    raw_res.insert(raw_res.end(), v.begin(), v.end());
  }
  const std::vector<double> clean_res = local_plane_residuals(r.cloud.positions, K);
  ASSERT_GT(raw_res.size(), 1000u);
  ASSERT_GT(clean_res.size(), r.cloud.size() / 2);
  const double raw_plane_rms = rms(raw_res), clean_plane_rms = rms(clean_res);
  const double raw_plane_med = median(raw_res), clean_plane_med = median(clean_res);

  std::printf(
      "3dj_test.oni, central %dx%d crop, %zu pixels valid in all 12 frames, mean depth %.3f m\n"
      "  (PS1080 quantisation step there: about %.0f mm)\n"
      "  per-pixel temporal std of the raw depth: mean %.3f mm, median %.3f mm\n"
      "  local plane-fit residual (5x5-pixel windows), raw single frames: RMS %.3f mm, median "
      "%.3f mm (%zu points)\n"
      "  same, 12 frames accumulated + robust filter: RMS %.3f mm, median %.3f mm (%zu points; "
      "%zu in -> %zu out)\n"
      "  reduction: RMS %.2fx, median %.2fx (filter h %.2f mm, noise sigma %.2f mm)\n"
      "  deviation from the per-pixel 12-frame mean depth (a staircase at this quantisation): "
      "raw RMS %.3f / median %.3f mm, cleaned RMS %.3f / median %.3f mm\n",
      W, H, t.pixels_valid_in_all, zsum / raw_n, 2.9 * (zsum / raw_n) * (zsum / raw_n),
      t.mean_std_m * 1e3, t.median_std_m * 1e3, raw_plane_rms * 1e3, raw_plane_med * 1e3,
      raw_res.size(), clean_plane_rms * 1e3, clean_plane_med * 1e3, clean_res.size(),
      r.filter.points_in, r.filter.points_out, raw_plane_rms / clean_plane_rms,
      raw_plane_med / clean_plane_med, r.filter.h * 1e3, r.filter.noise_sigma * 1e3, raw_rms * 1e3,
      raw_med * 1e3, clean_rms * 1e3, clean_med * 1e3);
  EXPECT_GT(raw_plane_rms, 0.001);  // the raw frames really are noisy
  EXPECT_LT(clean_plane_rms, 0.9 * raw_plane_rms);
  // Measured (clean_window, depth fused per pixel, depth-frame preset): plane-fit residual RMS
  // 3.99 -> 2.24 mm, median 2.38 -> 1.13 mm; deviation from the per-pixel mean RMS 56.2 -> 3.6
  // mm (the raw tails are level flips of the 43 mm quantisation step), median 4.42 -> 1.95 mm.
  EXPECT_LT(clean_plane_med, 0.5 * raw_plane_med);
  EXPECT_LT(clean_rms, 0.6 * raw_rms);  // against the per-pixel mean: RMS (outlier jumps) falls
}
#endif

}  // namespace
}  // namespace scanclean

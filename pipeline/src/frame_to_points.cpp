#include "scanclean/pipeline/frame_to_points.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "scanclean/core/errors.h"
#include "scanclean/pipeline/noise_model.h"

namespace scanclean {
namespace {

std::string frame_place(const RangeFrame& frame) {
  return "frame " + std::to_string(frame.index);
}

std::string size_text(int w, int h) {
  return std::to_string(w) + "x" + std::to_string(h);
}

// Distortion of normalized coordinates (OpenCV model: k1 k2 p1 p2 k3).
Eigen::Vector2d distort(const std::array<double, 5>& d, double x, double y) {
  const double r2 = x * x + y * y;
  const double radial = 1.0 + d[0] * r2 + d[1] * r2 * r2 + d[4] * r2 * r2 * r2;
  const double xd = x * radial + 2.0 * d[2] * x * y + d[3] * (r2 + 2.0 * x * x);
  const double yd = y * radial + d[2] * (r2 + 2.0 * y * y) + 2.0 * d[3] * x * y;
  return {xd, yd};
}

}  // namespace

void validate(const FrameToPointsOptions& o) {
  auto fail = [](const std::string& name, const std::string& value, const std::string& range) {
    throw OptionError("frame_to_points: option " + name + " = " + value + " is out of range; " +
                      "valid: " + range);
  };
  if (o.normal_stencil < 1 || o.normal_stencil > 32)
    fail("normal_stencil", std::to_string(o.normal_stencil), "[1, 32] pixels");
  if (!(o.max_depth_change_factor > 0 && o.max_depth_change_factor <= 1))
    fail("max_depth_change_factor", std::to_string(o.max_depth_change_factor), "(0, 1]");
  if (o.edge_margin_px < 0 || o.edge_margin_px > 32)
    fail("edge_margin_px", std::to_string(o.edge_margin_px), "[0, 32] pixels (0 = off)");
  if (!(o.min_depth_m >= 0) || !std::isfinite(o.min_depth_m))
    fail("min_depth_m", std::to_string(o.min_depth_m), ">= 0 metres (0 = no limit)");
  if (!(o.max_depth_m >= 0) || !std::isfinite(o.max_depth_m))
    fail("max_depth_m", std::to_string(o.max_depth_m), ">= 0 metres (0 = no limit)");
  if (o.max_depth_m > 0 && o.max_depth_m <= o.min_depth_m)
    fail("max_depth_m", std::to_string(o.max_depth_m), "greater than min_depth_m");
  if (!o.noise_model.empty() && o.noise_model != "nguyen2012" &&
      o.noise_model != "structured-light" && o.noise_model != "none")
    fail("noise_model", "\"" + o.noise_model + "\"",
         "\"\" (from the source), \"nguyen2012\", \"structured-light\" or \"none\"");
}

Eigen::Vector2d undistort_pixel(const Intrinsics& K, double u, double v) {
  const double xd = (u - K.cx) / K.fx;
  const double yd = (v - K.cy) / K.fy;
  if (!K.has_distortion()) return {xd, yd};
  double x = xd, y = yd;
  for (int it = 0; it < 50; ++it) {
    const double r2 = x * x + y * y;
    const double radial = 1.0 + K.dist[0] * r2 + K.dist[1] * r2 * r2 + K.dist[4] * r2 * r2 * r2;
    const double dx = 2.0 * K.dist[2] * x * y + K.dist[3] * (r2 + 2.0 * x * x);
    const double dy = K.dist[2] * (r2 + 2.0 * y * y) + 2.0 * K.dist[3] * x * y;
    const double nx = (xd - dx) / radial;
    const double ny = (yd - dy) / radial;
    const double change = std::abs(nx - x) + std::abs(ny - y);
    x = nx;
    y = ny;
    if (change < 1e-14) break;
  }
  return {x, y};
}

Eigen::Vector2d project_point(const Intrinsics& K, const Eigen::Vector3d& P) {
  const double x = P.x() / P.z(), y = P.y() / P.z();
  const Eigen::Vector2d d = distort(K.dist, x, y);
  return {K.fx * d.x() + K.cx, K.fy * d.y() + K.cy};
}

PointCloud frame_to_points(const RangeFrame& frame, const SourceInfo& info,
                           const FrameToPointsOptions& options, FrameToPointsStats* stats) {
  validate(options);
  const int W = frame.width(), H = frame.height();
  const std::string where = frame_place(frame);
  const std::string file = info.uri.empty() ? std::string("range frame") : info.uri;
  if (W <= 0 || H <= 0) throw InputError(file, where, "the frame has no depth image and no points");
  const bool have_points = frame.points.has_value();
  if (have_points && frame.points->data.size() != static_cast<std::size_t>(W) * H)
    throw InputError(file, where,
                     "points image holds " + std::to_string(frame.points->data.size()) +
                         " values, expected " + size_text(W, H));
  if (!have_points) {
    if (frame.depth.data.size() != static_cast<std::size_t>(W) * H)
      throw InputError(file, where,
                       "depth image holds " + std::to_string(frame.depth.data.size()) +
                           " values, expected " + size_text(W, H));
    if (!(frame.depth_unit_m > 0))
      throw InputError(file, where,
                       "depth unit must be positive, got " + std::to_string(frame.depth_unit_m));
  } else if (!frame.depth.empty() && (frame.depth.width != W || frame.depth.height != H)) {
    throw InputError(file, where,
                     "depth image is " + size_text(frame.depth.width, frame.depth.height) +
                         " but the points image is " + size_text(W, H));
  }
  if (frame.confidence && (frame.confidence->width != W || frame.confidence->height != H))
    throw InputError(file, where,
                     "confidence image is " +
                         size_text(frame.confidence->width, frame.confidence->height) +
                         ", expected " + size_text(W, H));
  if (frame.color && (frame.color->width != W || frame.color->height != H))
    throw InputError(file, where,
                     "colour image is " + size_text(frame.color->width, frame.color->height) +
                         ", expected " + size_text(W, H) + " (registered to the depth)");
  if (frame.sensor_normals &&
      (frame.sensor_normals->width != W || frame.sensor_normals->height != H))
    throw InputError(file, where,
                     "sensor-normal image is " +
                         size_text(frame.sensor_normals->width, frame.sensor_normals->height) +
                         ", expected " + size_text(W, H));

  const std::size_t N = static_cast<std::size_t>(W) * H;
  FrameToPointsStats st;
  st.pixels = N;

  // 1. Positions and validity.
  std::vector<Eigen::Vector3d> P(N, Eigen::Vector3d::Zero());
  std::vector<std::uint8_t> valid(N, 0);
  if (have_points) {
    for (std::size_t i = 0; i < N; ++i) {
      const Eigen::Vector3f& p = frame.points->data[i];
      if (p.allFinite() && p.z() > 0) {
        P[i] = p.cast<double>();
        valid[i] = 1;
      }
    }
  } else {
    Intrinsics K = frame.K.valid() ? frame.K : info.K;
    if (!K.valid())
      throw InputError(file, where,
                       "no camera intrinsics (fx fy cx cy) for the depth image; give them "
                       "(e.g. --fx --fy --cx --cy) or use a source that records them");
    if (K.width != W || K.height != H)
      throw InputError(file, where,
                       "intrinsics are for " + size_text(K.width, K.height) +
                           " images but the depth image is " + size_text(W, H));
    const bool distorted = K.has_distortion();
    for (int v = 0; v < H; ++v) {
      for (int u = 0; u < W; ++u) {
        const std::size_t i = static_cast<std::size_t>(v) * W + u;
        const std::uint16_t d = frame.depth.data[i];
        if (d == 0) continue;
        const double z = d * frame.depth_unit_m;
        const Eigen::Vector2d xy = distorted
                                       ? undistort_pixel(K, u, v)
                                       : Eigen::Vector2d((u - K.cx) / K.fx, (v - K.cy) / K.fy);
        P[i] = Eigen::Vector3d(xy.x() * z, xy.y() * z, z);
        valid[i] = 1;
      }
    }
  }
  for (std::size_t i = 0; i < N; ++i) {
    if (!valid[i]) continue;
    ++st.valid;
    const double z = P[i].z();
    if ((options.min_depth_m > 0 && z < options.min_depth_m) ||
        (options.max_depth_m > 0 && z > options.max_depth_m)) {
      valid[i] = 0;
      ++st.out_of_range;
    }
  }

  const double f = options.max_depth_change_factor;
  auto jump = [&](std::size_t a, std::size_t b) {
    const double za = P[a].z(), zb = P[b].z();
    return std::abs(za - zb) > f * std::min(za, zb);
  };

  // 2. Depth discontinuities (jumps between valid 4-neighbours), dilated by margin - 1.
  std::vector<std::uint8_t> edge(N, 0);
  const int m = options.edge_margin_px;
  if (m > 0) {
    for (int v = 0; v < H; ++v) {
      for (int u = 0; u < W; ++u) {
        const std::size_t i = static_cast<std::size_t>(v) * W + u;
        if (!valid[i]) continue;
        if (u + 1 < W && valid[i + 1] && jump(i, i + 1)) edge[i] = edge[i + 1] = 1;
        if (v + 1 < H && valid[i + W] && jump(i, i + W)) edge[i] = edge[i + W] = 1;
      }
    }
    const int r = m - 1;
    if (r > 0) {
      std::vector<std::uint8_t> tmp(N, 0);
      for (int v = 0; v < H; ++v)  // horizontal max filter
        for (int u = 0; u < W; ++u) {
          std::uint8_t e = 0;
          for (int k = std::max(0, u - r); k <= std::min(W - 1, u + r) && !e; ++k)
            e = edge[static_cast<std::size_t>(v) * W + k];
          tmp[static_cast<std::size_t>(v) * W + u] = e;
        }
      for (int v = 0; v < H; ++v)  // vertical max filter
        for (int u = 0; u < W; ++u) {
          std::uint8_t e = 0;
          for (int k = std::max(0, v - r); k <= std::min(H - 1, v + r) && !e; ++k)
            e = tmp[static_cast<std::size_t>(k) * W + u];
          edge[static_cast<std::size_t>(v) * W + u] = e;
        }
    }
  }

  // 3. Noise model.
  const std::string model = options.noise_model.empty() ? info.noise_model : options.noise_model;
  const bool nguyen = options.weights && model == "nguyen2012";

  // 4. Output, row-major.
  PointCloud cloud;
  cloud.grid.rows = H;
  cloud.grid.cols = W;
  cloud.grid.index.assign(N, -1);
  const int s = options.normal_stencil;
  for (int v = 0; v < H; ++v) {
    for (int u = 0; u < W; ++u) {
      const std::size_t i = static_cast<std::size_t>(v) * W + u;
      if (!valid[i]) continue;
      if (edge[i]) {
        ++st.edge_dropped;
        continue;
      }
      double conf = 1.0;
      if (frame.confidence) {
        const float c = frame.confidence->data[i];
        conf = std::isfinite(c) ? std::clamp(static_cast<double>(c), 0.0, 1.0) : 0.0;
        if (conf <= 0) {
          ++st.zero_weight;
          continue;
        }
      }
      const Eigen::Vector3d& p = P[i];
      Eigen::Vector3d n = Eigen::Vector3d::Zero();
      if (frame.sensor_normals) {
        const Eigen::Vector3f& sn = frame.sensor_normals->data[i];
        if (sn.allFinite() && sn.squaredNorm() > 0) n = sn.cast<double>().normalized();
      }
      if (n.isZero() && u - s >= 0 && u + s < W && v - s >= 0 && v + s < H) {
        const std::size_t l = i - s, r = i + s, up = i - static_cast<std::size_t>(s) * W,
                          dn = i + static_cast<std::size_t>(s) * W;
        const double z = p.z(), lim = f * z;
        bool ok = true;
        for (std::size_t q : {l, r, up, dn})
          if (!valid[q] || std::abs(P[q].z() - z) > lim) ok = false;
        if (ok) {
          const Eigen::Vector3d c = (P[r] - P[l]).cross(P[up] - P[dn]);
          const double len = c.norm();
          if (len > 0) n = c / len;
        }
      }
      if (!n.isZero()) {
        if (n.dot(p) > 0) n = -n;
      } else {
        ++st.no_normal;
      }
      double w = conf;
      if (nguyen) {
        double theta = 0;
        if (!n.isZero()) {
          const double c = std::min(1.0, std::abs(n.dot(p.normalized())));
          theta = std::acos(c);
        }
        w *= nguyen_weight(p.z(), theta, info.ps1080);
      }
      cloud.grid.index[i] = static_cast<std::int32_t>(cloud.positions.size());
      cloud.positions.push_back(p);
      cloud.normals.push_back(n.cast<float>());
      cloud.confidences.push_back(static_cast<float>(w));
      if (frame.color) {
        const auto& c = frame.color->data[i];
        cloud.colors.push_back({c[0], c[1], c[2], 255});
      }
    }
  }
  st.points = cloud.size();
  if (stats) *stats = st;
  return cloud;
}

}  // namespace scanclean

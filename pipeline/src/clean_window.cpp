#include "scanclean/pipeline/clean_window.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <optional>
#include <string>
#include <utility>

#include "scanclean/core/errors.h"

namespace scanclean {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

// Per-pixel fusion on the depth images themselves (frames of one size and one unit, depth only):
// the same rule as fuse_static_clouds (samples within factor x the median depth, averaged), but
// the fused depth is converted once (normals from the fused depth, flying pixels found on it)
// instead of converting every frame. The fused frame carries its points (ray x mean depth) and a
// confidence image kept / frames (x the frames' mean confidence when they have one). When every
// frame has a colour image of the depth's size, the fused pixel's colour is the mean of the
// colours of the samples kept (per channel, rounded), as fuse_static_clouds does for clouds.
std::optional<RangeFrame> fuse_depth_frames(const std::vector<RangeFrame>& frames,
                                            const FuseOptions& options, std::size_t* rejected,
                                            std::size_t* samples) {
  if (frames.size() < 2) return std::nullopt;
  const RangeFrame& f0 = frames.front();
  const int W = f0.depth.width, H = f0.depth.height;
  if (W <= 0 || H <= 0 || f0.K.fx <= 0 || f0.K.width != W || f0.K.height != H) return std::nullopt;
  for (const auto& f : frames)
    if (f.points || f.sensor_normals || f.depth.width != W || f.depth.height != H ||
        f.depth.data.size() != static_cast<std::size_t>(W) * H ||
        f.depth_unit_m != f0.depth_unit_m || f.K.fx != f0.K.fx || f.K.fy != f0.K.fy ||
        f.K.cx != f0.K.cx || f.K.cy != f0.K.cy || f.K.dist != f0.K.dist ||
        (f.confidence.has_value() != f0.confidence.has_value()) ||
        f.color.has_value() != f0.color.has_value() ||
        (f.color && (f.color->width != W || f.color->height != H ||
                     f.color->data.size() != static_cast<std::size_t>(W) * H)))
      return std::nullopt;  // fused as clouds (frame_to_points names a wrong colour size)
  const bool conf = f0.confidence.has_value();
  const bool colors = f0.color.has_value();
  const double nf = static_cast<double>(frames.size());
  RangeFrame out;
  out.index = frames.back().index;
  out.device_ts_us = frames.back().device_ts_us;
  out.host_ts_ns = frames.back().host_ts_ns;
  out.depth_unit_m = f0.depth_unit_m;
  out.K = f0.K;
  out.depth = Image<std::uint16_t>(W, H, 0);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  out.points = Image<Eigen::Vector3f>(W, H, Eigen::Vector3f(nan, nan, nan));
  out.confidence = Image<float>(W, H, 0.f);
  if (colors) out.color = Image<std::array<std::uint8_t, 3>>(W, H, {0, 0, 0});
  std::vector<std::size_t> dropped(static_cast<std::size_t>(H), 0), seen(dropped);
  tbb::parallel_for(0, H, [&](int v) {
    std::vector<std::pair<std::uint16_t, std::size_t>> zs;
    std::vector<std::uint16_t> sorted;
    for (int u = 0; u < W; ++u) {
      const std::size_t i = static_cast<std::size_t>(v) * W + u;
      zs.clear();
      for (std::size_t k = 0; k < frames.size(); ++k)
        if (const std::uint16_t d = frames[k].depth.data[i]; d != 0) zs.emplace_back(d, k);
      if (zs.empty()) continue;
      seen[v] += zs.size();
      sorted.clear();
      for (const auto& z : zs) sorted.push_back(z.first);
      const auto mid = sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2);
      std::nth_element(sorted.begin(), mid, sorted.end());
      const double med = *mid * f0.depth_unit_m;
      const double band = options.max_depth_deviation_factor * med;
      double sum = 0, csum = 0;
      std::array<std::uint32_t, 3> rgb{0, 0, 0};
      std::size_t kept = 0;
      for (const auto& [d, k] : zs) {
        const double z = d * f0.depth_unit_m;
        if (std::abs(z - med) > band) continue;
        sum += z;
        if (conf) {
          const float c = frames[k].confidence->data[i];
          csum += std::isfinite(c) ? std::clamp(static_cast<double>(c), 0.0, 1.0) : 0.0;
        }
        if (colors)
          for (int ch = 0; ch < 3; ++ch) rgb[ch] += frames[k].color->data[i][ch];
        ++kept;
      }
      dropped[v] += zs.size() - kept;
      const double z = sum / static_cast<double>(kept);
      const Eigen::Vector2d xy = undistort_pixel(f0.K, u, v);
      out.points->data[i] = Eigen::Vector3f(static_cast<float>(xy.x() * z),
                                            static_cast<float>(xy.y() * z), static_cast<float>(z));
      out.depth.data[i] =
          static_cast<std::uint16_t>(std::clamp(std::lround(z / f0.depth_unit_m), 1L, 65535L));
      const double c = conf ? csum / nf : static_cast<double>(kept) / nf;
      out.confidence->data[i] = static_cast<float>(c);
      if (colors)
        for (int ch = 0; ch < 3; ++ch)
          out.color->data[i][ch] = static_cast<std::uint8_t>((rgb[ch] + kept / 2) / kept);
    }
  });
  std::size_t d = 0, n = 0;
  for (int v = 0; v < H; ++v) {
    d += dropped[v];
    n += seen[v];
  }
  if (rejected) *rejected = d;
  if (samples) *samples = n;
  return out;
}

}  // namespace

void validate(const WindowOptions& options) {
  validate(options.points);
  if (!(options.fusion.max_depth_deviation_factor > 0 &&
        options.fusion.max_depth_deviation_factor <= 1))
    throw OptionError("fuse: option max_depth_deviation_factor = " +
                      std::to_string(options.fusion.max_depth_deviation_factor) +
                      " is out of range; valid: (0, 1]");
  if (!options.raw) validate(options.filter);
}

WindowInput window_input(const std::vector<RangeFrame>& frames, const SourceInfo& info,
                         const WindowOptions& options) {
  const auto t0 = Clock::now();
  WindowInput in;
  in.frames = frames.size();
  if (!options.raw && options.fuse && options.fuse_depth && frames.size() > 1) {
    std::size_t rejected = 0, samples = 0;
    if (auto fused = fuse_depth_frames(frames, options.fusion, &rejected, &samples)) {
      FrameToPointsStats fs;
      in.cloud = frame_to_points(*fused, info, options.points, &fs);
      in.points_in = samples;
      for (std::size_t k = 0; k < frames.size(); ++k) {
        std::size_t valid = 0;
        for (const std::uint16_t dk : frames[k].depth.data) valid += dk != 0 ? 1 : 0;
        in.min_points_per_frame = k == 0 ? valid : std::min(in.min_points_per_frame, valid);
        in.max_points_per_frame = std::max(in.max_points_per_frame, valid);
      }
      in.edge_dropped = fs.edge_dropped;
      in.out_of_range = fs.out_of_range;
      in.no_normal = fs.no_normal;
      in.points_fused = in.cloud.size();
      in.fusion_rejected = rejected;
      in.seconds_points = seconds_since(t0);
      return in;
    }
  }
  std::vector<PointCloud> clouds(frames.size());
  std::vector<FrameToPointsStats> stats(frames.size());
  tbb::parallel_for(std::size_t{0}, frames.size(), [&](std::size_t i) {
    clouds[i] = frame_to_points(frames[i], info, options.points, &stats[i]);
  });
  for (std::size_t i = 0; i < clouds.size(); ++i) {
    const std::size_t n = clouds[i].size();
    in.points_in += n;
    in.min_points_per_frame = i == 0 ? n : std::min(in.min_points_per_frame, n);
    in.max_points_per_frame = std::max(in.max_points_per_frame, n);
    in.edge_dropped += stats[i].edge_dropped;
    in.out_of_range += stats[i].out_of_range;
    in.no_normal += stats[i].no_normal;
  }
  std::optional<PointCloud> fused;
  if (!options.raw && options.fuse && clouds.size() > 1)
    fused = fuse_static_clouds(clouds, options.fusion, &in.fusion_rejected);
  if (fused) {
    in.points_fused = fused->size();
    in.cloud = std::move(*fused);
  } else {
    in.fusion_rejected = 0;
    in.cloud = accumulate_clouds(clouds);
  }
  in.seconds_points = seconds_since(t0);
  return in;
}

WindowResult clean_window_input(WindowInput&& input, const WindowOptions& options) {
  WindowResult r;
  if (options.raw) {
    r.cloud = std::move(input.cloud);
    return r;
  }
  const auto t = Clock::now();
  input.cloud.grid = {};  // the filter takes the points as a set
  if (options.keep_input) r.input = input.cloud;
  FilterResult f = robust_filter(input.cloud, options.filter);
  input.cloud = {};  // the counts stay; the points are no longer needed
  r.seconds_filter = seconds_since(t);
  r.cloud = std::move(f.cloud);
  r.outliers = std::move(f.outliers);
  r.filter = f.stats;
  return r;
}

WindowResult clean_window(const std::vector<RangeFrame>& frames, const SourceInfo& info,
                          const WindowOptions& options) {
  validate(options);
  return clean_window_input(window_input(frames, info, options), options);
}

}  // namespace scanclean

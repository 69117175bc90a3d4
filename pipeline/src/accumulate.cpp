#include "scanclean/pipeline/accumulate.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "scanclean/core/errors.h"

namespace scanclean {

PointCloud accumulate_clouds(const std::vector<PointCloud>& clouds) {
  PointCloud out;
  std::size_t total = 0;
  for (const auto& c : clouds) total += c.size();
  out.positions.reserve(total);
  for (const auto& c : clouds) append(out, c);
  out.grid = {};
  return out;
}

FilterResult accumulate_and_clean(const std::vector<RangeFrame>& frames, const SourceInfo& info,
                                  const FrameToPointsOptions& points_options,
                                  const FilterOptions& filter_options) {
  std::vector<PointCloud> clouds;
  clouds.reserve(frames.size());
  for (const auto& f : frames) clouds.push_back(frame_to_points(f, info, points_options));
  return robust_filter(accumulate_clouds(clouds), filter_options);
}

TemporalSpread temporal_depth_spread(const std::vector<RangeFrame>& frames) {
  if (frames.empty()) throw InputError("temporal_depth_spread: no frames");
  TemporalSpread t;
  t.width = frames.front().depth.width;
  t.height = frames.front().depth.height;
  t.frames = frames.size();
  const std::size_t N = static_cast<std::size_t>(t.width) * t.height;
  std::vector<double> sum(N, 0.0), sum2(N, 0.0);
  t.valid_count = Image<std::uint16_t>(t.width, t.height, 0);
  for (const auto& f : frames) {
    if (f.depth.width != t.width || f.depth.height != t.height || f.depth.data.size() != N)
      throw InputError("temporal_depth_spread", "frame " + std::to_string(f.index),
                       "depth image is " + std::to_string(f.depth.width) + "x" +
                           std::to_string(f.depth.height) + ", expected " +
                           std::to_string(t.width) + "x" + std::to_string(t.height));
    for (std::size_t i = 0; i < N; ++i) {
      if (f.depth.data[i] == 0) continue;
      const double z = f.depth.data[i] * f.depth_unit_m;
      sum[i] += z;
      sum2[i] += z * z;
      ++t.valid_count.data[i];
    }
  }
  t.mean_m = Image<float>(t.width, t.height, 0.f);
  t.std_m = Image<float>(t.width, t.height, 0.f);
  std::vector<double> all;
  for (std::size_t i = 0; i < N; ++i) {
    const double n = t.valid_count.data[i];
    if (n == 0) continue;
    const double mean = sum[i] / n;
    // Two-pass-quality variance from the sums is fine at these magnitudes (z <= 10 m, mm steps).
    const double var = std::max(0.0, sum2[i] / n - mean * mean);
    t.mean_m.data[i] = static_cast<float>(mean);
    t.std_m.data[i] = static_cast<float>(std::sqrt(var));
    if (t.valid_count.data[i] == frames.size()) all.push_back(std::sqrt(var));
  }
  t.pixels_valid_in_all = all.size();
  if (!all.empty()) {
    double s = 0;
    for (double v : all) s += v;
    t.mean_std_m = s / all.size();
    std::nth_element(all.begin(), all.begin() + all.size() / 2, all.end());
    t.median_std_m = all[all.size() / 2];
  }
  return t;
}

}  // namespace scanclean

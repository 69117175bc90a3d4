#include "scanclean/pipeline/accumulate.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
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

std::optional<PointCloud> fuse_static_clouds(const std::vector<PointCloud>& clouds,
                                             const FuseOptions& options, std::size_t* rejected) {
  if (!(options.max_depth_deviation_factor > 0 && options.max_depth_deviation_factor <= 1))
    throw OptionError("fuse: option max_depth_deviation_factor = " +
                      std::to_string(options.max_depth_deviation_factor) +
                      " is out of range; valid: (0, 1]");
  if (clouds.empty() || clouds.front().grid.empty()) return std::nullopt;
  const int rows = clouds.front().grid.rows, cols = clouds.front().grid.cols;
  for (const auto& c : clouds)
    if (c.grid.rows != rows || c.grid.cols != cols ||
        c.grid.index.size() != static_cast<std::size_t>(rows) * cols)
      return std::nullopt;
  const std::size_t cells = static_cast<std::size_t>(rows) * cols;
  const double frames = static_cast<double>(clouds.size());
  PointCloud out;
  out.grid.rows = rows;
  out.grid.cols = cols;
  out.grid.index.assign(cells, -1);
  const bool normals = std::all_of(clouds.begin(), clouds.end(), [](const PointCloud& c) {
    return c.has_normals() || c.empty();
  });
  const bool colors = std::all_of(clouds.begin(), clouds.end(),
                                  [](const PointCloud& c) { return c.has_colors() || c.empty(); });
  std::size_t dropped = 0;
  std::vector<std::pair<double, std::size_t>> samples;  // (z, cloud) of one pixel
  std::vector<double> zs;
  for (std::size_t cell = 0; cell < cells; ++cell) {
    samples.clear();
    for (std::size_t k = 0; k < clouds.size(); ++k) {
      const std::int32_t i = clouds[k].grid.index[cell];
      if (i >= 0) samples.emplace_back(clouds[k].positions[static_cast<std::size_t>(i)].z(), k);
    }
    if (samples.empty()) continue;
    zs.clear();
    for (const auto& sm : samples) zs.push_back(sm.first);
    const auto mid = zs.begin() + static_cast<std::ptrdiff_t>(zs.size() / 2);
    std::nth_element(zs.begin(), mid, zs.end());
    const double z_med = *mid;
    const double band = options.max_depth_deviation_factor * std::abs(z_med);
    Eigen::Vector3d p = Eigen::Vector3d::Zero(), n = Eigen::Vector3d::Zero();
    double w = 0;
    std::array<double, 4> rgba{0, 0, 0, 0};
    std::size_t kept = 0;
    for (const auto& [z, k] : samples) {
      if (std::abs(z - z_med) > band) {
        ++dropped;
        continue;
      }
      const auto i = static_cast<std::size_t>(clouds[k].grid.index[cell]);
      p += clouds[k].positions[i];
      if (normals) n += clouds[k].normals[i].cast<double>();
      if (colors)
        for (int ch = 0; ch < 4; ++ch) rgba[ch] += clouds[k].colors[i][ch];
      w += clouds[k].has_confidences() ? static_cast<double>(clouds[k].confidences[i]) : 1.0;
      ++kept;
    }
    // kept >= 1: the median sample itself is within the band.
    out.grid.index[cell] = static_cast<std::int32_t>(out.positions.size());
    out.positions.push_back(p / static_cast<double>(kept));
    if (normals) {
      const double len = n.norm();
      out.normals.push_back(len > 1e-9 ? Eigen::Vector3f((n / len).cast<float>())
                                       : Eigen::Vector3f::Zero());
    }
    out.confidences.push_back(static_cast<float>(std::clamp(w / frames, 0.0, 1.0)));
    if (colors) {  // the mean colour of the samples kept
      std::array<std::uint8_t, 4> c{};
      for (int ch = 0; ch < 4; ++ch)
        c[ch] = static_cast<std::uint8_t>(std::lround(rgba[ch] / static_cast<double>(kept)));
      out.colors.push_back(c);
    }
  }
  if (rejected) *rejected = dropped;
  return out;
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

#include "scanclean/pipeline/clean_window.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
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

#pragma once
//! Tiny recording folders for the OpenNI2 tests: a few 160x120 frames whose depth is a closed-form
//! function of (frame index, u, v), written with the replay module's RecordingWriter and served
//! through the real OpenNI2 API by the virtual-sensor driver.

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "scanclean/core/range_frame.h"
#include "scanclean/replay/recording_writer.h"

namespace scanclean::test {

//! Depth (in counts) at (u, v) of the frame with this index; 0 (invalid) on a sparse lattice.
//! Values span 300..60299 so that the .oni codec sees large steps and the whole 16-bit range.
inline std::uint16_t vs_depth(std::uint64_t index, int u, int v) {
  if ((u + 5 * v + static_cast<int>(index)) % 11 == 0) return 0;
  return static_cast<std::uint16_t>(300 + (u * 4099 + v * 613 + index * 7919) % 60000);
}

struct VsFixture {
  std::filesystem::path folder;
  std::vector<std::uint64_t> indices;
  std::vector<std::int64_t> timestamps_us;
  SessionMetadata session;
};

//! Writes `frames` frames (indices first_index, first_index+1, ...; timestamps 33,367 µs apart
//! starting at 2,000,000 µs) of width x height into `folder`. fx = fy = 200 px.
inline VsFixture write_vs_fixture(const std::filesystem::path& folder, int frames = 5,
                                  int width = 160, int height = 120, double unit_m = 0.001,
                                  bool ps1080 = false, std::uint64_t first_index = 10) {
  VsFixture fx;
  fx.folder = folder;
  SessionMetadata& s = fx.session;
  s.device.kind = "test";
  s.device.vendor = "scanclean-tests";
  s.device.name = "fixture";
  s.device.serial = "SN-FIXTURE-1";
  s.width = width;
  s.height = height;
  s.unit_m = unit_m;
  s.K.fx = s.K.fy = 200.0;
  s.K.cx = width / 2.0;
  s.K.cy = height / 2.0;
  s.K.width = width;
  s.K.height = height;
  if (ps1080) {
    s.noise_model = "nguyen2012";
    s.ps1080 = Ps1080Params{120.0, 0.1042, 7.5, 4.0};
  }
  RecordingWriter writer(folder, s);
  for (int i = 0; i < frames; ++i) {
    RangeFrame f;
    f.index = first_index + static_cast<std::uint64_t>(i);
    f.device_ts_us = 2'000'000 + static_cast<std::int64_t>(i) * 33'367;
    f.host_ts_ns = 1'000'000'000LL + i * 33'367'000LL;
    f.depth_unit_m = unit_m;
    f.K = s.K;
    f.depth = Image<std::uint16_t>(width, height);
    for (int v = 0; v < height; ++v)
      for (int u = 0; u < width; ++u) f.depth(u, v) = vs_depth(f.index, u, v);
    writer.write(f);
    fx.indices.push_back(f.index);
    fx.timestamps_us.push_back(f.device_ts_us);
  }
  writer.finish();
  return fx;
}

//! Number of pixels of `frame` that differ from vs_depth(expected_index, u, v).
inline std::size_t vs_mismatches(const RangeFrame& frame, std::uint64_t expected_index) {
  std::size_t bad = 0;
  for (int v = 0; v < frame.depth.height; ++v)
    for (int u = 0; u < frame.depth.width; ++u)
      if (frame.depth(u, v) != vs_depth(expected_index, u, v)) ++bad;
  return bad;
}

}  // namespace scanclean::test

#pragma once
//! Small deterministic recordings for the replay tests (no RNG: pixel values are a closed-form
//! function of the frame index, so any reader can recompute them).

#include <cstdint>
#include <filesystem>
#include <string>

#include "scanclean/core/errors.h"
#include "scanclean/core/range_frame.h"
#include "scanclean/replay/recording_format.h"

namespace scanclean::test {

inline SessionMetadata fixture_session(int width = 16, int height = 12) {
  SessionMetadata s;
  s.device = {"openni2",   "PrimeSense", "PS1080", "openni2://1d27/0601@1/2",
              "1d27:0601", "1209250148", "5.8.22"};
  s.width = width;
  s.height = height;
  s.unit_m = 0.0001;
  s.K = Intrinsics::from_fov(width, height, 1.0226, 0.7966);
  s.K.dist = {0.1, -0.25, 0.001, -0.002, 0.05};
  s.K.source = "calibration";
  s.noise_model = "nguyen2012";
  s.ps1080 = Ps1080Params{120.0, 0.10419999808073044, 7.5, 4.0};
  s.registration = "depth_to_color";
  s.extrinsics_depth_to_color = DepthToColor{{1, 0, 0, 0, 1, 0, 0, 0, 1}, {0.025, 0, 0}};
  s.created = "2026-11-22T21:00:00Z";
  return s;
}

//! Depth value of pixel (u, v) in the frame with this index (0 on a sparse pattern = invalid).
inline std::uint16_t fixture_depth(std::uint64_t index, int u, int v) {
  if ((u + 2 * v + static_cast<int>(index)) % 7 == 0) return 0;
  return static_cast<std::uint16_t>((u * 2311 + v * 977 + index * 40503 + 5000) % 65536);
}

//! Frame `index` at 30 fps nominal; with_confidence adds an exactly representable confidence.
inline RangeFrame fixture_frame(const SessionMetadata& s, std::uint64_t index,
                                bool with_confidence) {
  RangeFrame f;
  f.index = index;
  f.device_ts_us = 1'000'000 + static_cast<std::int64_t>(index) * 33'333;
  f.host_ts_ns = 5'000'000'000LL + static_cast<std::int64_t>(index) * 33'334'000;
  f.depth_unit_m = s.unit_m;
  f.K = s.K;
  f.depth = Image<std::uint16_t>(s.width, s.height);
  for (int v = 0; v < s.height; ++v)
    for (int u = 0; u < s.width; ++u) f.depth(u, v) = fixture_depth(index, u, v);
  if (with_confidence) {
    Image<float> c(s.width, s.height);
    for (int v = 0; v < s.height; ++v)
      for (int u = 0; u < s.width; ++u)
        c(u, v) = static_cast<float>(((u * 131 + v * 17 + index * 7) % 65536) / 65535.0);
    f.confidence = std::move(c);
  }
  return f;
}

}  // namespace scanclean::test

#pragma once
//! A small recording folder (format v1) written with the replay module, for the factory,
//! contract and pipeline-command tests. Needs scanclean::replay.

#include <cmath>
#include <cstdint>
#include <filesystem>

#include "pipeline/pipeline_fixtures.h"
#include "scanclean/replay/recording_format.h"
#include "scanclean/replay/recording_writer.h"

namespace scanclean::test {

//! `frames` frames of w x h: a plane at 1 m tilted 20 degrees with a box in front, 1 mm units,
//! Gaussian noise of 1.5 mm (seeded per frame), indices 0.., timestamps 33.333 ms apart.
inline void write_fixture_recording(const std::filesystem::path& folder, int frames = 5, int w = 64,
                                    int h = 48) {
  const Intrinsics K = test_camera(w, h);
  SessionMetadata s;
  s.device.vendor = "scanclean";
  s.device.name = "fixture";
  s.width = w;
  s.height = h;
  s.unit_m = 0.001;
  s.K = K;
  s.K.source = "calibration";
  s.noise_model = "nguyen2012";
  RecordingWriter writer(folder, s, RecordingWriterOptions{false});
  for (int i = 0; i < frames; ++i) {
    RangeFrame f = plane_frame(K, 1.0, tilted_normal(20), 0.001, 0.0015,
                               static_cast<std::uint32_t>(100 + i), static_cast<std::uint64_t>(i));
    for (int v = h / 3; v < h / 2; ++v)
      for (int u = w / 3; u < w / 2; ++u) f.depth(u, v) = 800;  // a box 20 cm in front
    f.host_ts_ns = 1000000 + static_cast<std::int64_t>(i) * 33333333;
    writer.write(f);
  }
  writer.finish();
}

}  // namespace scanclean::test

// FrameRecorder (the acquisition stage's recorder): frames with a colour image are recorded with
// it, and a source that restarts its indices is shifted so that the recorded index increases.

#include "scanclean/replay/frame_recorder.h"

#include <gtest/gtest.h>

#include <array>
#include <cstdint>

#include "scanclean/replay/recording_reader.h"
#include "support/data_paths.h"
#include "support/synthetic.h"

namespace scanclean {
namespace {

RangeFrame coloured_frame(std::uint64_t index, std::uint8_t red) {
  RangeFrame f = test::coloured_wall_frame(1000, red);
  f.index = index;
  f.device_ts_us = static_cast<std::int64_t>(index) * 33333;
  return f;
}

TEST(FrameRecorderTest, RecordsTheColourImageAndKeepsIndicesIncreasing) {
  const auto dir = test::make_temp_dir("frame_recorder") / "rec";
  SourceInfo info;
  info.uri = "test://colour";
  info.kind = "test";
  {
    FrameRecorder rec(dir);
    rec.write(info, coloured_frame(5, 100));
    rec.write(info, coloured_frame(1, 200));  // the source restarted its indices
    rec.finish();
    EXPECT_EQ(rec.frames_written(), 2u);
  }
  RecordingReader reader(dir);
  ASSERT_EQ(reader.frame_count(), 2u);
  EXPECT_EQ(reader.record(0).index, 5u);
  EXPECT_GT(reader.record(1).index, reader.record(0).index);
  for (std::size_t i = 0; i < 2; ++i) {
    const auto rgb = reader.read_color(i);
    ASSERT_EQ(rgb.width, 8);
    ASSERT_EQ(rgb.height, 6);
    const std::uint8_t red = i == 0 ? 100 : 200;
    for (int v = 0; v < 6; ++v)
      for (int u = 0; u < 8; ++u) {
        EXPECT_EQ(rgb(u, v)[0], red);
        EXPECT_EQ(rgb(u, v)[1], 10 * u);
        EXPECT_EQ(rgb(u, v)[2], 10 * v);
      }
  }
}

}  // namespace
}  // namespace scanclean

#include "scanclean/replay/replay_source.h"

#include <gtest/gtest.h>

#include <chrono>
#include <vector>

#include "replay_fixtures.h"
#include "scanclean/core/errors.h"
#include "scanclean/replay/recording_reader.h"
#include "scanclean/replay/recording_writer.h"
#include "support/data_paths.h"

namespace scanclean {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

fs::path make_recording(const std::string& tag, const std::vector<std::uint64_t>& indices,
                        const std::vector<std::int64_t>& device_ts_us = {}) {
  const auto dir = test::make_temp_dir(tag);
  const SessionMetadata s = test::fixture_session();
  RecordingWriter w(dir, s);
  for (std::size_t k = 0; k < indices.size(); ++k) {
    RangeFrame f = test::fixture_frame(s, indices[k], false);
    if (!device_ts_us.empty()) f.device_ts_us = device_ts_us[k];
    w.write(f);
  }
  w.finish();
  return dir;
}

TEST(ReplaySourceTest, DeliversEveryFrameThenEndOfStreamRepeatedly) {
  const std::vector<std::uint64_t> indices{0, 1, 2, 5, 6, 20};  // gaps: 3 and 13 dropped
  const auto dir = make_recording("replay_contract", indices);
  auto src = make_replay_source(dir);
  src->open();
  const SourceInfo info = src->info();
  EXPECT_EQ(info.kind, "recording");
  EXPECT_EQ(info.uri, dir.string());
  EXPECT_FALSE(info.is_live);
  ASSERT_TRUE(info.frame_count);
  EXPECT_EQ(*info.frame_count, indices.size());
  EXPECT_EQ(info.vendor, "PrimeSense");
  EXPECT_EQ(info.noise_model, "nguyen2012");
  EXPECT_EQ(info.depth_unit_m, 0.0001);
  EXPECT_TRUE(info.K.valid());

  const SessionMetadata s = test::fixture_session();
  std::vector<std::uint64_t> got;
  std::int64_t last_ts = -1;
  RangeFrame f;
  while (src->next(f, 100ms) == ReadStatus::kOk) {
    got.push_back(f.index);
    EXPECT_GT(f.device_ts_us, last_ts);
    last_ts = f.device_ts_us;
    EXPECT_EQ(f.width(), s.width);
    EXPECT_EQ(f.height(), s.height);
    EXPECT_EQ(f.depth.size(), static_cast<std::size_t>(s.width) * s.height);
    EXPECT_EQ(f.depth.data, test::fixture_frame(s, f.index, false).depth.data);
    EXPECT_EQ(f.K.width, s.width);
    EXPECT_EQ(f.depth_unit_m, s.unit_m);
  }
  EXPECT_EQ(got, indices);  // gaps preserved, nothing lost, nothing repeated
  for (int k = 0; k < 3; ++k) EXPECT_EQ(src->next(f, 10ms), ReadStatus::kEndOfStream);
  src->close();
  // Reopen: the stream starts again from the first frame.
  src->open();
  ASSERT_EQ(src->next(f, 10ms), ReadStatus::kOk);
  EXPECT_EQ(f.index, 0u);
  fs::remove_all(dir);
}

TEST(ReplaySourceTest, OpenReportsBadRecordingAsInputError) {
  const auto dir = test::make_temp_dir("replay_bad");
  auto src = make_replay_source(dir / "nothing_here");
  EXPECT_THROW(src->open(), InputError);
  fs::remove_all(dir);
}

//! A fake clock: sleep advances time instantly and records each sleep.
struct FakeClock {
  std::chrono::nanoseconds t{1'000'000'000};
  std::vector<std::chrono::nanoseconds> sleeps;
  ReplayClock clock() {
    ReplayClock c;
    c.now = [this] { return t; };
    c.sleep = [this](std::chrono::nanoseconds d) {
      sleeps.push_back(d);
      t += d;
    };
    return c;
  }
};

TEST(ReplaySourceTest, RecordedPacingFollowsDeviceTimestampsOnFakeClock) {
  // Deltas 20 ms, 50 ms, 0 (repeated timestamp: host delta used), 10 ms.
  const auto dir = make_recording("replay_fake_clock", {0, 1, 2, 3, 4},
                                  {100000, 120000, 170000, 170000, 180000});
  FakeClock fake;
  auto src = make_replay_source(dir, Pacing::kRecorded, fake.clock());
  src->open();
  RangeFrame f;
  std::vector<std::chrono::nanoseconds> delivered;
  ReadStatus st;
  while ((st = src->next(f, 1000ms)) == ReadStatus::kOk) delivered.push_back(fake.t);
  EXPECT_EQ(st, ReadStatus::kEndOfStream);
  ASSERT_EQ(delivered.size(), 5u);
  EXPECT_EQ(delivered[1] - delivered[0], 20ms);
  EXPECT_EQ(delivered[2] - delivered[1], 50ms);
  // Equal device timestamps: the host timestamps (33.334 ms apart in the fixture) pace the step.
  EXPECT_EQ(delivered[3] - delivered[2], 33'334'000ns);
  EXPECT_EQ(delivered[4] - delivered[3], 10ms);
  fs::remove_all(dir);
}

TEST(ReplaySourceTest, RecordedPacingReturnsTimeoutWhenFrameIsNotDueYet) {
  const auto dir = make_recording("replay_timeout", {0, 1}, {0, 500000});  // 500 ms apart
  FakeClock fake;
  auto src = make_replay_source(dir, Pacing::kRecorded, fake.clock());
  src->open();
  RangeFrame f;
  ASSERT_EQ(src->next(f, 100ms), ReadStatus::kOk);
  const auto t0 = fake.t;
  int timeouts = 0;
  ReadStatus st;
  while ((st = src->next(f, 100ms)) == ReadStatus::kTimeout) ++timeouts;
  EXPECT_EQ(st, ReadStatus::kOk);
  EXPECT_EQ(timeouts, 4);  // 4 x 100 ms waits, then the remaining 100 ms inside the 5th call
  EXPECT_EQ(fake.t - t0, 500ms);
  EXPECT_EQ(f.index, 1u);
  fs::remove_all(dir);
}

TEST(ReplaySourceTest, RecordedPacingOnRealClockTakesTheRecordedTime) {
  const auto dir = make_recording("replay_real_clock", {0, 1, 2}, {0, 20000, 40000});
  auto paced = make_replay_source(dir, Pacing::kRecorded);
  RangeFrame f;
  paced->open();
  const auto t0 = std::chrono::steady_clock::now();
  int n = 0;
  while (paced->next(f, 1000ms) == ReadStatus::kOk) ++n;
  const auto paced_time = std::chrono::steady_clock::now() - t0;
  EXPECT_EQ(n, 3);
  EXPECT_GE(paced_time, 35ms);  // 2 x 20 ms, loosely
  fs::remove_all(dir);
}

}  // namespace
}  // namespace scanclean

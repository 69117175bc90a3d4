// The capture-and-clean pipeline on the virtual sensor through the real OpenNI2 API, paced in
// real time (fast frame rates and small frames keep each test to a few seconds): every delivered
// frame is recorded while cleaning falls behind, across a reconnect and up to Ctrl-C, and a
// replay of the recording cleans the same windows as the live run.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "scanclean/drivers/make_range_source.h"
#include "scanclean/pipeline/pipeline.h"
#include "scanclean/replay/frame_recorder.h"
#include "scanclean/replay/recording_reader.h"
#include "support/data_paths.h"

namespace scanclean {
namespace {

using namespace std::chrono_literals;

// A run of run_pipeline on `uri` with every frame recorded to `folder`.
struct LiveRun {
  PipelineStats stats;
  std::vector<WindowOutput> windows;
};

LiveRun run_recorded(const std::string& uri, PipelineOptions o,
                     const std::filesystem::path& folder) {
  auto source = make_range_source(uri);
  FrameRecorder recorder(folder);
  o.record = [&](const SourceInfo& info, const RangeFrame& f) { recorder.write(info, f); };
  LiveRun run;
  run.stats =
      run_pipeline(*source, o, [&](WindowOutput&& w) { run.windows.push_back(std::move(w)); });
  source->close();
  recorder.finish();
  return run;
}

PipelineOptions small_windows(std::size_t frames) {
  PipelineOptions o;
  o.accumulate = frames;
  o.window.filter.threads = 2;
  return o;
}

// The recording holds `n` frames with strictly increasing indices.
void expect_recording(const std::filesystem::path& folder, std::uint64_t n) {
  RecordingReader reader(folder);
  ASSERT_EQ(reader.frame_count(), n);
  for (std::size_t i = 1; i < reader.frame_count(); ++i)
    EXPECT_GT(reader.record(i).index, reader.record(i - 1).index) << "row " << i;
}

TEST(LivePipelineTest, SlowCleaningSkipsWholeWindowsButRecordsEveryFrame) {
  const auto dir = test::make_temp_dir("live_slow");
  PipelineOptions o = small_windows(10);
  o.memory_budget_bytes = 1;  // a window waits only when no other does
  o.before_cleaning = [](std::size_t) { std::this_thread::sleep_for(400ms); };
  // 90 frames at 60 fps: a window of 10 frames every 167 ms, cleaned in more than 400 ms.
  const LiveRun run =
      run_recorded("vsensor://pattern?w=160&h=120&n=90&fps=60&pace=realtime", o, dir / "rec");
  const PipelineStats& st = run.stats;
  EXPECT_EQ(st.stop, StopReason::kEndOfStream);
  // Every frame read is in the recording (OpenNI2 itself may lose a frame on a loaded machine:
  // an index gap, counted).
  EXPECT_GE(st.frames_read, 50u);
  EXPECT_EQ(st.frames_recorded, st.frames_read);
  expect_recording(dir / "rec", st.frames_read);
  // Cleaning falls behind: whole windows are skipped, each named with its frames, and every
  // window is either output or skipped, in order.
  const std::size_t total = (st.frames_read + 9) / 10;
  EXPECT_GE(st.skipped.size(), 2u);
  EXPECT_EQ(st.windows + st.skipped.size(), total);
  EXPECT_EQ(st.frames_cleaned + 10 * st.skipped.size(), st.frames_read);
  ASSERT_EQ(run.windows.size(), st.windows);
  std::vector<bool> seen(total, false);
  for (std::size_t i = 0; i < run.windows.size(); ++i) {
    const WindowOutput& w = run.windows[i];
    if (i > 0) {
      EXPECT_GT(w.window, run.windows[i - 1].window);
    }
    ASSERT_LT(w.window, total);
    seen[w.window] = true;
    EXPECT_EQ(w.first_frame, 10 * w.window);
    EXPECT_EQ(w.frames, std::min<std::uint64_t>(10, st.frames_read - 10 * w.window));
    EXPECT_FALSE(w.cloud.empty());
  }
  for (const SkippedWindow& s : st.skipped) {
    ASSERT_LT(s.window, total);
    EXPECT_FALSE(seen[s.window]) << "window " << s.window << " both skipped and output";
    EXPECT_EQ(s.first_frame, 10 * s.window);
    EXPECT_EQ(s.last_frame, 10 * s.window + 9);
    EXPECT_GE(s.last_index - s.first_index, 9u);
  }
  EXPECT_TRUE(seen[total - 1]) << "the last window is never skipped";
}

TEST(LivePipelineTest, FileSourcesWaitInsteadOfSkipping) {
  // The same slow cleaning on the recording of a live run: nothing is skipped.
  const auto dir = test::make_temp_dir("live_file");
  PipelineOptions o = small_windows(10);
  o.window.raw = true;
  const LiveRun live =
      run_recorded("vsensor://pattern?w=160&h=120&n=40&fps=60&pace=realtime", o, dir / "rec");
  const std::uint64_t n = live.stats.frames_read;
  ASSERT_GE(n, 31u);
  ASSERT_EQ(live.stats.frames_recorded, n);
  PipelineOptions slow = small_windows(10);
  slow.memory_budget_bytes = 1;
  slow.before_cleaning = [](std::size_t) { std::this_thread::sleep_for(100ms); };
  auto source = make_range_source((dir / "rec").string());
  std::size_t windows = 0;
  const PipelineStats st = run_pipeline(*source, slow, [&](WindowOutput&&) { ++windows; });
  EXPECT_EQ(st.frames_read, n);
  EXPECT_TRUE(st.skipped.empty());
  EXPECT_EQ(windows, (n + 9) / 10);
  EXPECT_EQ(st.frames_cleaned, n);
}

TEST(LivePipelineTest, DisconnectWithReconnectLosesNoRecordedFrame) {
  const auto dir = test::make_temp_dir("live_reconnect");
  PipelineOptions o = small_windows(10);
  o.window.raw = true;  // the frames are the point here
  o.acquisition.reconnect_attempts = 3;
  o.acquisition.reconnect_delay = 50ms;
  // The device goes away after 25 frames; every reopened device does the same.
  const LiveRun run =
      run_recorded("vsensor://pattern?w=160&h=120&n=60&fps=60&pace=realtime&disconnect_after=25", o,
                   dir / "rec");
  const PipelineStats& st = run.stats;
  EXPECT_GE(st.disconnects, 2u);
  EXPECT_GE(st.reconnects, 1u);
  EXPECT_GE(st.frames_read, 50u);  // at least two devices' 25 frames
  EXPECT_EQ(st.frames_recorded, st.frames_read);
  expect_recording(dir / "rec", st.frames_read);  // indices shifted to keep increasing
  std::uint64_t in_windows = 0;
  for (const auto& w : run.windows) in_windows += w.frames;
  EXPECT_EQ(in_windows, st.frames_read);
}

TEST(LivePipelineTest, InterruptMidWindowCleansWhatWasCaptured) {
  const auto dir = test::make_temp_dir("live_interrupt");
  PipelineOptions o = small_windows(10);
  std::atomic<std::uint64_t> used{0};
  o.on_frame = [&](std::uint64_t n) { used = n; };
  o.acquisition.keep_going = [&] { return used.load() < 15; };  // Ctrl-C in the middle of window 1
  const LiveRun run =
      run_recorded("vsensor://pattern?w=160&h=120&n=300&fps=60&pace=realtime", o, dir / "rec");
  EXPECT_EQ(run.stats.stop, StopReason::kInterrupted);
  EXPECT_EQ(run.stats.frames_read, 15u);
  EXPECT_EQ(run.stats.frames_recorded, 15u);
  expect_recording(dir / "rec", 15);
  ASSERT_EQ(run.windows.size(), 2u);
  EXPECT_EQ(run.windows[1].frames, 5u);  // the partial window is cleaned, not lost
  EXPECT_FALSE(run.windows[1].cloud.empty());
  EXPECT_EQ(run.stats.frames_cleaned, 15u);
}

TEST(LivePipelineTest, ReplayOfTheRecordingCleansTheSameWindows) {
  const auto dir = test::make_temp_dir("live_replay");
  PipelineOptions o = small_windows(10);
  const LiveRun live =
      run_recorded("vsensor://pattern?w=160&h=120&n=30&fps=60&pace=realtime", o, dir / "rec");
  ASSERT_TRUE(live.stats.skipped.empty());
  ASSERT_EQ(live.windows.size(), 3u);
  PipelineOptions replay = small_windows(10);
  replay.window.filter.threads = 1;  // and the thread count does not matter
  auto source = make_range_source((dir / "rec").string());
  std::vector<WindowOutput> again;
  run_pipeline(*source, replay, [&](WindowOutput&& w) { again.push_back(std::move(w)); });
  ASSERT_EQ(again.size(), live.windows.size());
  for (std::size_t i = 0; i < again.size(); ++i) {
    SCOPED_TRACE("window " + std::to_string(i));
    EXPECT_EQ(again[i].window, live.windows[i].window);
    EXPECT_EQ(again[i].frames, live.windows[i].frames);
    ASSERT_EQ(again[i].cloud.size(), live.windows[i].cloud.size());
    EXPECT_EQ(again[i].cloud.positions, live.windows[i].cloud.positions);
    EXPECT_EQ(again[i].cloud.normals, live.windows[i].cloud.normals);
  }
}

}  // namespace
}  // namespace scanclean

#include "scanclean/replay/recording_source.h"

#include <gtest/gtest.h>

#include <deque>

#include "replay_fixtures.h"
#include "scanclean/core/errors.h"
#include "scanclean/replay/recording_reader.h"
#include "scanclean/replay/replay_source.h"
#include "support/data_paths.h"

namespace scanclean {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

//! A scripted inner source: a queue of outcomes; kOk entries deliver fixture frames.
class ScriptedSource final : public RangeSource {
 public:
  struct Step {
    ReadStatus status;
    std::uint64_t index = 0;
  };
  ScriptedSource(SessionMetadata s, std::vector<Step> steps, bool known_size)
      : s_(std::move(s)), script_(std::move(steps)), known_size_(known_size) {}
  void open() override {
    ++opens;
    steps_.assign(script_.begin(), script_.end());
  }
  ReadStatus next(RangeFrame& frame, std::chrono::milliseconds) override {
    if (steps_.empty()) return ReadStatus::kEndOfStream;
    const Step st = steps_.front();
    steps_.pop_front();
    if (st.status == ReadStatus::kOk) frame = test::fixture_frame(s_, st.index, true);
    return st.status;
  }
  SourceInfo info() const override {
    SourceInfo info;
    info.uri = "scripted://";
    info.kind = "openni2";
    info.vendor = "PrimeSense";
    info.name = "PS1080";
    info.serial = "A1";
    info.usb_id = "1d27:0601";
    info.is_live = true;
    info.K = s_.K;
    if (!known_size_) info.K.width = info.K.height = 0;
    info.depth_unit_m = s_.unit_m;
    info.noise_model = "nguyen2012";
    info.ps1080 = s_.ps1080;
    return info;
  }
  void close() override { ++closes; }
  std::string last_error() const override { return "scripted error"; }
  int opens = 0, closes = 0;

 private:
  SessionMetadata s_;
  std::vector<Step> script_;
  std::deque<Step> steps_;
  bool known_size_;
};

TEST(RecordingSourceTest, WritesExactlyWhatItForwards) {
  for (bool known_size : {true, false}) {
    const auto dir = test::make_temp_dir("recsrc") / "rec";
    const SessionMetadata s = test::fixture_session();
    using S = ScriptedSource::Step;
    auto inner = std::make_unique<ScriptedSource>(s,
                                                  std::vector<S>{{ReadStatus::kOk, 10},
                                                                 {ReadStatus::kTimeout},
                                                                 {ReadStatus::kOk, 11},
                                                                 {ReadStatus::kError},
                                                                 {ReadStatus::kOk, 14}},
                                                  known_size);
    ScriptedSource* raw = inner.get();
    auto rec = make_recording_source(std::move(inner), dir);
    rec->open();
    EXPECT_EQ(rec->info().uri, "scripted://");  // the decorator is invisible
    EXPECT_EQ(rec->info().kind, "openni2");
    EXPECT_EQ(fs::exists(dir / "session.json"), known_size);
    std::vector<ReadStatus> statuses;
    std::vector<RangeFrame> delivered;
    RangeFrame f;
    for (int k = 0; k < 7; ++k) {
      statuses.push_back(rec->next(f, 10ms));
      if (statuses.back() == ReadStatus::kOk) delivered.push_back(f);
      if (statuses.back() == ReadStatus::kError) {
        EXPECT_EQ(rec->last_error(), "scripted error");
      }
    }
    EXPECT_EQ(statuses,
              (std::vector<ReadStatus>{ReadStatus::kOk, ReadStatus::kTimeout, ReadStatus::kOk,
                                       ReadStatus::kError, ReadStatus::kOk,
                                       ReadStatus::kEndOfStream, ReadStatus::kEndOfStream}));
    ASSERT_EQ(delivered.size(), 3u);
    // End of stream finalized the recording; it holds exactly the delivered frames.
    RecordingReader r(dir);
    EXPECT_TRUE(r.session().finalized);
    EXPECT_EQ(r.session().device.kind, "openni2");
    EXPECT_EQ(r.session().device.uri, "scripted://");
    EXPECT_EQ(r.session().device.serial, "A1");
    EXPECT_EQ(r.session().K.fx, s.K.fx);
    ASSERT_TRUE(r.session().ps1080);
    ASSERT_EQ(r.frame_count(), delivered.size());
    for (std::size_t i = 0; i < delivered.size(); ++i) {
      const RangeFrame g = r.read_frame(i);
      EXPECT_EQ(g.index, delivered[i].index);
      EXPECT_EQ(g.device_ts_us, delivered[i].device_ts_us);
      EXPECT_EQ(g.host_ts_ns, delivered[i].host_ts_ns);
      EXPECT_EQ(g.depth.data, delivered[i].depth.data);
      ASSERT_TRUE(g.confidence);
      EXPECT_EQ(g.confidence->data, delivered[i].confidence->data);
    }
    rec->close();
    EXPECT_EQ(raw->closes, 1);
    fs::remove_all(dir.parent_path());
  }
}

TEST(RecordingSourceTest, ReconnectAppendsAndKeepsIndicesIncreasing) {
  const auto dir = test::make_temp_dir("recsrc_reconnect") / "rec";
  const SessionMetadata s = test::fixture_session();
  using S = ScriptedSource::Step;
  // The inner device restarts at index 1 after each open (as a replugged sensor does).
  auto rec = make_recording_source(
      std::make_unique<ScriptedSource>(
          s,
          std::vector<S>{{ReadStatus::kOk, 1}, {ReadStatus::kOk, 2}, {ReadStatus::kDisconnected}},
          true),
      dir);
  RangeFrame f;
  rec->open();
  EXPECT_EQ(rec->next(f, 10ms), ReadStatus::kOk);
  EXPECT_EQ(rec->next(f, 10ms), ReadStatus::kOk);
  EXPECT_EQ(rec->next(f, 10ms), ReadStatus::kDisconnected);
  rec->close();
  EXPECT_TRUE(RecordingReader(dir).session().finalized);
  rec->open();
  EXPECT_EQ(rec->next(f, 10ms), ReadStatus::kOk);
  EXPECT_EQ(f.index, 1u);  // forwarded unchanged
  EXPECT_FALSE(RecordingReader(dir).session().finalized);
  rec->close();
  RecordingReader r(dir);
  ASSERT_EQ(r.frame_count(), 3u);
  EXPECT_EQ(r.record(0).index, 1u);
  EXPECT_EQ(r.record(1).index, 2u);
  EXPECT_EQ(r.record(2).index, 3u);  // shifted to keep increasing
  EXPECT_EQ(r.read_frame(2).depth.data, test::fixture_frame(s, 1, false).depth.data);
  fs::remove_all(dir.parent_path());
}

TEST(RecordingSourceTest, ReplayOfARecordingRecordsIdentically) {
  // Record a replay: the second recording equals the first frame by frame.
  const auto base = test::make_temp_dir("recsrc_chain");
  const SessionMetadata s = test::fixture_session();
  {
    RecordingWriter w(base / "a", s);
    for (std::uint64_t i : {0, 2, 3}) w.write(test::fixture_frame(s, i, true));
    w.finish();
  }
  auto rec = make_recording_source(make_replay_source(base / "a"), base / "b");
  rec->open();
  RangeFrame f;
  while (rec->next(f, 10ms) == ReadStatus::kOk) {
  }
  rec->close();
  RecordingReader a(base / "a"), b(base / "b");
  ASSERT_EQ(a.frame_count(), b.frame_count());
  EXPECT_EQ(b.session().device.kind, "recording");
  EXPECT_EQ(b.session().device.serial, s.device.serial);
  for (std::size_t i = 0; i < a.frame_count(); ++i) {
    EXPECT_EQ(a.record(i).index, b.record(i).index);
    EXPECT_EQ(a.read_frame(i).depth.data, b.read_frame(i).depth.data);
    EXPECT_EQ(a.read_frame(i).confidence->data, b.read_frame(i).confidence->data);
  }
  fs::remove_all(base);
}

}  // namespace
}  // namespace scanclean

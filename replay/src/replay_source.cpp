#include "scanclean/replay/replay_source.h"

#include <optional>
#include <thread>
#include <vector>

#include "scanclean/core/errors.h"
#include "scanclean/replay/recording_reader.h"

namespace scanclean {

ReplayClock ReplayClock::steady() {
  ReplayClock c;
  c.now = [] {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(
        std::chrono::steady_clock::now().time_since_epoch());
  };
  c.sleep = [](std::chrono::nanoseconds d) {
    if (d.count() > 0) std::this_thread::sleep_for(d);
  };
  return c;
}

namespace {

class ReplaySource final : public RangeSource {
 public:
  ReplaySource(std::filesystem::path folder, Pacing pacing, ReplayClock clock)
      : folder_(std::move(folder)), pacing_(pacing), clock_(std::move(clock)) {}

  void open() override {
    reader_.emplace(folder_);
    next_ = 0;
    start_.reset();
    // Offsets of each frame from the first, on the recorded time line.
    offsets_.assign(reader_->frame_count(), std::chrono::nanoseconds(0));
    for (std::size_t i = 1; i < offsets_.size(); ++i) {
      const FrameRecord& a = reader_->record(i - 1);
      const FrameRecord& b = reader_->record(i);
      std::chrono::nanoseconds step(0);
      if (b.device_ts_us > a.device_ts_us)
        step = std::chrono::microseconds(b.device_ts_us - a.device_ts_us);
      else if (b.host_ts_ns > a.host_ts_ns)
        step = std::chrono::nanoseconds(b.host_ts_ns - a.host_ts_ns);
      offsets_[i] = offsets_[i - 1] + step;
    }
    info_ = info_from_session(reader_->session(), folder_.string());
    info_.frame_count = reader_->frame_count();
    info_.warnings = reader_->warnings();
  }

  ReadStatus next(RangeFrame& frame, std::chrono::milliseconds timeout) override {
    if (!reader_) {
      error_ = "next() called before open()";
      return ReadStatus::kError;
    }
    if (next_ >= reader_->frame_count()) return ReadStatus::kEndOfStream;
    if (pacing_ == Pacing::kRecorded && start_) {
      const std::chrono::nanoseconds due = *start_ + offsets_[next_];
      const std::chrono::nanoseconds wait = due - clock_.now();
      if (wait > timeout) {
        clock_.sleep(timeout);
        return ReadStatus::kTimeout;
      }
      if (wait.count() > 0) clock_.sleep(wait);
    }
    frame = reader_->read_frame(next_);
    if (pacing_ == Pacing::kRecorded && !start_) start_ = clock_.now() - offsets_[next_];
    ++next_;
    return ReadStatus::kOk;
  }

  SourceInfo info() const override { return info_; }
  void close() override { reader_.reset(); }
  std::string last_error() const override { return error_; }

 private:
  std::filesystem::path folder_;
  Pacing pacing_;
  ReplayClock clock_;
  std::optional<RecordingReader> reader_;
  std::vector<std::chrono::nanoseconds> offsets_;
  std::optional<std::chrono::nanoseconds> start_;
  std::size_t next_ = 0;
  SourceInfo info_;
  std::string error_;
};

}  // namespace

std::unique_ptr<RangeSource> make_replay_source(const std::filesystem::path& folder,
                                                Pacing pacing) {
  return make_replay_source(folder, pacing, ReplayClock::steady());
}

std::unique_ptr<RangeSource> make_replay_source(const std::filesystem::path& folder, Pacing pacing,
                                                ReplayClock clock) {
  if (!clock.now || !clock.sleep) throw OptionError("make_replay_source: clock is incomplete");
  return std::make_unique<ReplaySource>(folder, pacing, std::move(clock));
}

}  // namespace scanclean

#include "scanclean/replay/recording_source.h"

#include <optional>

#include "scanclean/core/errors.h"

namespace scanclean {

namespace {

class RecordingSource final : public RangeSource {
 public:
  RecordingSource(std::unique_ptr<RangeSource> inner, std::filesystem::path folder,
                  RecordingWriterOptions options)
      : inner_(std::move(inner)), folder_(std::move(folder)), options_(options) {}

  ~RecordingSource() override {
    try {
      if (writer_) writer_->finish();
    } catch (...) {  // a destructor must not throw; the recording stays valid (not finalized)
    }
  }

  void open() override {
    inner_->open();
    info_ = inner_->info();
    if (!writer_ && info_.K.width > 0 && info_.K.height > 0)
      writer_.emplace(folder_, session_from_info(info_, info_.K.width, info_.K.height), options_);
  }

  ReadStatus next(RangeFrame& frame, std::chrono::milliseconds timeout) override {
    const ReadStatus status = inner_->next(frame, timeout);
    if (status == ReadStatus::kEndOfStream) {
      if (writer_) writer_->finish();
      return status;
    }
    if (status != ReadStatus::kOk) return status;
    if (!writer_)
      writer_.emplace(folder_, session_from_info(info_, frame.depth.width, frame.depth.height),
                      options_);
    if (last_recorded_ && frame.index + offset_ <= *last_recorded_)
      offset_ = *last_recorded_ + 1 - frame.index;  // the inner source restarted its indices
    if (offset_ == 0) {
      writer_->write(frame);
    } else {
      RangeFrame shifted = frame;
      shifted.index += offset_;
      writer_->write(shifted);
    }
    last_recorded_ = frame.index + offset_;
    return status;
  }

  SourceInfo info() const override { return inner_->info(); }

  void close() override {
    inner_->close();
    if (writer_) writer_->finish();
  }

  std::string last_error() const override { return inner_->last_error(); }

 private:
  std::unique_ptr<RangeSource> inner_;
  std::filesystem::path folder_;
  RecordingWriterOptions options_;
  std::optional<RecordingWriter> writer_;
  SourceInfo info_;
  std::optional<std::uint64_t> last_recorded_;
  std::uint64_t offset_ = 0;
};

}  // namespace

std::unique_ptr<RangeSource> make_recording_source(std::unique_ptr<RangeSource> inner,
                                                   const std::filesystem::path& folder,
                                                   const RecordingWriterOptions& options) {
  if (!inner) throw OptionError("make_recording_source: no inner source");
  return std::make_unique<RecordingSource>(std::move(inner), folder, options);
}

}  // namespace scanclean

#include "scanclean/replay/frame_recorder.h"

#include <utility>

#include "scanclean/replay/recording_format.h"

namespace scanclean {

FrameRecorder::FrameRecorder(std::filesystem::path folder, RecordingWriterOptions options)
    : folder_(std::move(folder)), options_(options) {}

FrameRecorder::~FrameRecorder() {
  try {
    finish();
  } catch (...) {  // a destructor must not throw; the recording stays valid (not finalized)
  }
}

void FrameRecorder::write(const SourceInfo& info, const RangeFrame& frame) {
  if (!writer_)
    writer_.emplace(folder_, session_from_info(info, frame.depth.width, frame.depth.height),
                    options_);
  if (last_recorded_ && frame.index + offset_ <= *last_recorded_)
    offset_ = *last_recorded_ + 1 - frame.index;  // the source restarted its indices
  // The colour image, when the frame has one, is recorded beside the depth (color/).
  auto put = [this](const RangeFrame& f) {
    if (f.color)
      writer_->write(f, *f.color);
    else
      writer_->write(f);
  };
  if (offset_ == 0) {
    put(frame);
  } else {
    RangeFrame shifted = frame;
    shifted.index += offset_;
    put(shifted);
  }
  last_recorded_ = frame.index + offset_;
  ++written_;
}

void FrameRecorder::finish() {
  if (writer_) writer_->finish();
}

}  // namespace scanclean

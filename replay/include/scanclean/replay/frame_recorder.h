#pragma once
//! \file frame_recorder.h
//! Writes delivered frames to a recording folder (format v1), for a pipeline's acquisition stage
//! (PipelineOptions::record): the frames it reads are recorded there, not through a source
//! decorator (recording_source.h), so that the recording never depends on what the pipeline pulls.

#include <cstdint>
#include <filesystem>
#include <optional>

#include "scanclean/core/range_frame.h"
#include "scanclean/core/range_source.h"
#include "scanclean/replay/recording_writer.h"

namespace scanclean {

class FrameRecorder {
 public:
  //! Nothing is created before the first frame.
  explicit FrameRecorder(std::filesystem::path folder, RecordingWriterOptions options = {});
  //! Finishes the recording (errors ignored: it stays a valid, non-finalized recording).
  ~FrameRecorder();
  FrameRecorder(const FrameRecorder&) = delete;
  FrameRecorder& operator=(const FrameRecorder&) = delete;

  //! Appends `frame`; the first frame creates the recording (session_from_info(info, its depth
  //! size)). A source that restarted its indices (a reconnect) is shifted so that the recorded
  //! index keeps increasing. The frame's colour image, if any, is recorded too.
  //! \throw as RecordingWriter (IoError, InputError).
  void write(const SourceInfo& info, const RangeFrame& frame);
  //! session.json "finalized": true. Idempotent. \throw IoError.
  void finish();
  std::uint64_t frames_written() const { return written_; }

 private:
  std::filesystem::path folder_;
  RecordingWriterOptions options_;
  std::optional<RecordingWriter> writer_;
  std::optional<std::uint64_t> last_recorded_;
  std::uint64_t offset_ = 0;
  std::uint64_t written_ = 0;
};

}  // namespace scanclean

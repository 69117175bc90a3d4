#pragma once
//! \file recording_writer.h
//! Writes a recording folder, format v1 (recording_format.h, recordings/README.md), crash-safely:
//! session.json first (atomically, "finalized": false), then for each frame its PNG files
//! (each atomically: temporary file, fsync, rename) and only then its frames.csv line (one
//! write(2), then fsync). A writer killed at any moment leaves a folder that RecordingReader
//! reads up to the last complete frame. finish() rewrites session.json with "finalized": true
//! and the frame count.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>

#include "scanclean/core/range_frame.h"
#include "scanclean/replay/recording_format.h"

namespace scanclean {

struct RecordingWriterOptions {
  //! fsync frames.csv after each line (the crash-safety guarantee). Frame PNGs and session.json
  //! are always synced before their rename. Turning this off only trades power-loss safety of
  //! the index for speed; a killed process still leaves a readable prefix.
  bool sync_index = true;
};

class RecordingWriter {
 public:
  //! Creates `folder` (and parents) and writes session.json and the frames.csv header.
  //! `session.created` is set to the current UTC time when empty; finalized/frame_count are
  //! ignored (a new recording is never finalized).
  //! \throw OptionError (session has no positive width/height or unit_m), IoError (folder holds a
  //! session.json already, or cannot be written).
  RecordingWriter(const std::filesystem::path& folder, const SessionMetadata& session,
                  const RecordingWriterOptions& options = {});
  //! Does NOT finalize: a writer destroyed without finish() leaves a valid, non-finalized
  //! recording (exactly what a crash leaves).
  ~RecordingWriter();
  RecordingWriter(RecordingWriter&&) noexcept;
  RecordingWriter& operator=(RecordingWriter&&) noexcept;

  //! Appends one frame: depth (must be session width x height, unit equal to session.unit_m)
  //! and, when present, the confidence image (quantized to round(c * 65535), c clamped to
  //! [0, 1]). frame.index must be greater than the previous frame's index (gaps are kept).
  //! frame.points and frame.sensor_normals are not stored by format v1. Writing after finish()
  //! reopens the recording (session.json goes back to "finalized": false until finish()).
  //! \throw InputError (wrong size, unit or index order, no depth image), IoError.
  void write(const RangeFrame& frame);
  //! Same, plus the frame's colour image (any size; stored losslessly as color/NNNNNN.png,
  //! 8-bit RGB). \throw as write(frame), and InputError for an empty colour image.
  void write(const RangeFrame& frame, const RgbImage& color);

  //! Rewrites session.json atomically with "finalized": true and frame_count. Idempotent.
  //! \throw IoError.
  void finish();

  std::size_t frames_written() const;
  const std::filesystem::path& folder() const;
  const SessionMetadata& session() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace scanclean

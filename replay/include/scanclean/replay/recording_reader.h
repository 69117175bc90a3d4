#pragma once
//! \file recording_reader.h
//! Reads and validates a recording folder, format v1 (recording_format.h). Accepts recordings
//! whose writer was killed: a non-finalized session, a trailing partial frames.csv line (ignored
//! with a warning) and, in a non-finalized recording only, a last row whose files are missing
//! (also ignored with a warning). Everything else that is wrong is an InputError naming the file,
//! the row (frames.csv line) and what was expected.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "scanclean/core/range_frame.h"
#include "scanclean/replay/recording_format.h"

namespace scanclean {

//! One row of frames.csv. Paths are relative to the recording folder ("" = none).
struct FrameRecord {
  std::uint64_t index = 0;
  std::int64_t device_ts_us = 0;
  std::int64_t host_ts_ns = 0;
  std::string depth, color, confidence;
  std::uint32_t flags = 0;  //!< reserved in v1 (written as 0; unknown bits are ignored)
  std::size_t line = 0;     //!< 1-based line of frames.csv (for messages)
};

class RecordingReader {
 public:
  //! Reads session.json and frames.csv and checks that every referenced file exists.
  //! \throw InputError (missing session.json, wrong format version, bad field types, malformed or
  //! non-increasing frames.csv rows, missing files, frame count differing from a finalized
  //! session), IoError.
  explicit RecordingReader(const std::filesystem::path& folder);
  ~RecordingReader();
  RecordingReader(RecordingReader&&) noexcept;
  RecordingReader& operator=(RecordingReader&&) noexcept;

  const SessionMetadata& session() const;
  std::size_t frame_count() const;
  //! Row i of frames.csv (i < frame_count(); \throw std::out_of_range otherwise).
  const FrameRecord& record(std::size_t i) const;
  //! Decodes frame i: index and timestamps from frames.csv, depth (session width x height,
  //! depth_unit_m = session unit_m), K from the session, confidence (value / 65535) when
  //! recorded. Thread-safe (const, no shared mutable state).
  //! \throw InputError naming the PNG and the frames.csv row (not 16-bit grayscale, size differing
  //! from session.json, corrupt), std::out_of_range for i >= frame_count().
  RangeFrame read_frame(std::size_t i) const;
  //! Absolute path of frame i's colour image, empty when none was recorded.
  std::filesystem::path color_file(std::size_t i) const;
  //! Decodes frame i's colour image (PNG or JPEG, 8-bit, 1, 3 or 4 channels; gray is expanded,
  //! alpha dropped). \throw InputError naming the file (no colour recorded for this frame, not
  //! decodable, more than 2^26 pixels, not 8-bit).
  RgbImage read_color(std::size_t i) const;
  //! Recoverable problems found while opening (e.g. "ignored a partial last line").
  const std::vector<std::string>& warnings() const;
  const std::filesystem::path& folder() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace scanclean

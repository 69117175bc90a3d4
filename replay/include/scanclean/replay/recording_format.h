#pragma once
//! \file recording_format.h
//! Recording folder format v1 ("scanclean-rec/1", docs/SENSORS.md §8, recordings/README.md): the
//! session metadata (session.json) and its JSON encoding. No JSON types appear here; the
//! encoding lives in recording_format.cpp.

#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

#include "scanclean/core/range_frame.h"
#include "scanclean/core/range_source.h"

namespace scanclean {

//! The format tag written into session.json; readers accept exactly this major version.
inline constexpr const char* kRecordingFormat = "scanclean-rec/1";
//! The metadata file and the frame index of a recording folder.
inline constexpr const char* kSessionFileName = "session.json";
inline constexpr const char* kFramesFileName = "frames.csv";
//! The exact header line of frames.csv (without the newline).
inline constexpr const char* kFramesCsvHeader =
    "index,device_ts_us,host_ts_ns,depth,color,confidence,flags";

//! An 8-bit RGB image (R, G, B per pixel, row-major), for the optional colour stream.
using RgbImage = Image<std::array<std::uint8_t, 3>>;

//! The sensor a recording came from (session.json "device").
struct RecordedDevice {
  std::string kind;  //!< SourceInfo::kind of the recorded source ("openni2", "oni", ...); may be ""
  std::string vendor, name, uri;
  std::string usb;  //!< "vvvv:pppp" USB vendor:product id, or ""
  std::string serial, firmware;
};

//! Rigid transform from the depth camera to the colour camera (session.json
//! "extrinsics_depth_to_color"): x_color = R x_depth + T, T in metres.
struct DepthToColor {
  std::array<double, 9> R{1, 0, 0, 0, 1, 0, 0, 0, 1};  //!< row-major rotation
  std::array<double, 3> T{};                           //!< metres
};

//! Everything session.json holds. Units: unit_m metres per depth count; intrinsics in pixels.
struct SessionMetadata {
  std::string format = kRecordingFormat;
  RecordedDevice device;
  int width = 0, height = 0;  //!< depth image size (pixels); every depth PNG has exactly this size
  double unit_m = 0.001;      //!< metres per depth count (0.001 = 1 mm, 0.0001 = 100 um)
  Intrinsics K;               //!< K.width/K.height equal width/height
  std::string noise_model = "none";  //!< "nguyen2012", "structured-light" or "none"
  std::optional<Ps1080Params> ps1080;
  std::string registration = "off";  //!< "off" or "depth_to_color"
  std::optional<DepthToColor> extrinsics_depth_to_color;
  std::string created;                       //!< ISO 8601 UTC, e.g. "2026-11-22T21:30:00Z"
  bool finalized = false;                    //!< true only after RecordingWriter::finish()
  std::optional<std::uint64_t> frame_count;  //!< present when finalized: rows in frames.csv
};

//! Session metadata for recording frames of `info` whose depth images are width x height.
//! Copies device, intrinsics (K.width/K.height set to width/height; when info.K has no positive
//! fx/fy the intrinsics are stored as zeros), unit, noise model and PS1080 constants. \throw
//! OptionError when width or height is not positive.
SessionMetadata session_from_info(const SourceInfo& info, int width, int height);

//! The SourceInfo a replay of this session presents: kind "recording", the given uri, the
//! recorded device's vendor/name/serial/usb/firmware, intrinsics, unit, noise model, PS1080
//! constants, frame_count when finalized, is_live false.
SourceInfo info_from_session(const SessionMetadata& session, const std::string& uri);

//! session.json text (pretty-printed JSON, UTF-8, ends with a newline).
std::string session_to_json(const SessionMetadata& session);

//! Parses and validates session.json text. `file` names the file in error messages.
//! \throw InputError naming the file and the field (e.g. "field depth.width: expected a positive
//! integer, got \"640\"") for syntax errors, a wrong format tag, missing fields or wrong types.
SessionMetadata session_from_json(const std::string& text, const std::string& file);

//! Reads <folder>/session.json. \throw InputError (missing, malformed), IoError.
SessionMetadata read_session(const std::filesystem::path& folder);

//! Writes <folder>/session.json atomically (temporary file, fsync, rename). \throw IoError.
void write_session(const std::filesystem::path& folder, const SessionMetadata& session);

//! True when `path` is a folder holding a session.json (a recording folder, possibly one whose
//! writer was killed). Does not validate the content; RecordingReader does.
bool is_recording_folder(const std::filesystem::path& path);

//! The current UTC time as ISO 8601 ("YYYY-MM-DDTHH:MM:SSZ").
std::string utc_now_iso8601();

}  // namespace scanclean

#pragma once
//! \file range_source.h
//! The one interface every frame producer implements: live OpenNI2 sensors, .oni files, the
//! virtual sensor, recording folders, depth-image sequences and structured-light captures.
//! Expected stream outcomes are values (ReadStatus); only bad input, bad options and missing
//! devices throw (see errors.h).

#include <chrono>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "scanclean/core/range_frame.h"

namespace scanclean {

enum class ReadStatus {
  kOk,            //!< a frame was delivered
  kTimeout,       //!< no frame within the timeout; try again
  kEndOfStream,   //!< a finite source has no more frames (reported once, then again on each call)
  kDisconnected,  //!< the device went away; close() and open() again to reconnect
  kError          //!< the frame could not be read; last_error() says why
};

const char* to_string(ReadStatus status);

//! What a source is, for metadata, the noise model and the user.
struct SourceInfo {
  std::string uri;  //!< what was opened, e.g. "openni2://", "rec/session1", "x.oni"
  std::string
      kind;  //!< "openni2", "oni", "vsensor", "recording", "depth-images", "structured-light"
  std::string vendor, name, serial, usb_id, firmware;
  bool is_live = false;                      //!< a physical device (pacing is real time)
  std::optional<std::uint64_t> frame_count;  //!< known for finite sources
  Intrinsics K;                              //!< nominal or calibrated
  double depth_unit_m = 0.001;
  std::string noise_model =
      "none";  //!< "nguyen2012" (PrimeSense class), "structured-light", "none"
  std::optional<Ps1080Params> ps1080;
  //! Recoverable problems found while opening (e.g. a recording's partial last frames.csv line,
  //! ignored); the program prints them.
  std::vector<std::string> warnings;
};

class RangeSource {
 public:
  virtual ~RangeSource() = default;
  RangeSource() = default;
  RangeSource(const RangeSource&) = delete;
  RangeSource& operator=(const RangeSource&) = delete;

  //! Opens the source. \throw UnavailableError (no device, no driver), InputError (unreadable
  //! recording or capture), IoError.
  virtual void open() = 0;
  //! The next frame, waiting at most `timeout` for it.
  virtual ReadStatus next(RangeFrame& frame, std::chrono::milliseconds timeout) = 0;
  //! Description of the opened source (valid after open()).
  virtual SourceInfo info() const = 0;
  //! Releases the device or files; open() may be called again afterwards.
  virtual void close() {}
  //! Human-readable reason for the last kError or kDisconnected outcome.
  virtual std::string last_error() const { return {}; }
};

}  // namespace scanclean

#pragma once
//! \file openni2_source.h
//! Range sources through the real OpenNI2 API (Debian's libOpenNI2 2.2.0.33): live sensors,
//! .oni recordings and the project's virtual sensor (drivers/openni2_vsensor). No OpenNI types
//! appear here; only drivers/openni2/src/*.cpp include OpenNI headers.
//!
//! Driver folder: OpenNI2 loads its drivers from <folder of libOpenNI2.so.0>/OpenNI2/Drivers.
//! Build-tree programs and tests use <build>/oni (virtual sensor + .oni player); live rigs run
//! with LD_LIBRARY_PATH=<build>/oni-live (adds PS1080/PSLink); an installed program uses
//! <prefix>/lib/scanclean/oni, PS1080/PSLink included (docs/SENSORS.md §1, §3; cmake/).
//!
//! OpenNI::initialize() is called once per process through a reference-counted context: the
//! first open source initializes OpenNI2, the last closed one shuts it down.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "scanclean/core/range_source.h"

namespace scanclean {

struct OpenNI2Options {
  //! Ask live devices for PIXEL_FORMAT_DEPTH_100_UM (0.1 mm units) instead of DEPTH_1_MM. Files
  //! and the virtual sensor keep their recorded format (setVideoMode is never called on files).
  bool depth_100um = false;
  //! A live device (or vsensor) that times out this many consecutive next() calls is reported
  //! kDisconnected (0 = never; the disconnect listener still applies).
  int disconnect_timeouts = 30;
};

//! Throws OptionError naming the option when out of range (disconnect_timeouts < 0).
void validate(const OpenNI2Options& options);

//! A RangeSource for
//!   "openni2://"                 the first device OpenNI2 lists (any sensor),
//!   "openni2://<device uri>"     a specific device (URI as `scanclean devices` prints it),
//!   "<file>.oni"                 an OpenNI recording, played losslessly in manual mode
//!                                (PlaybackControl speed -1, no repeat; never seek),
//!   "vsensor://<abs folder>?..." the virtual sensor replaying a recording folder
//!                                (parameters: drivers/openni2_vsensor/src/frame_provider.h).
//! open() throws UnavailableError "no depth sensor found; run scanclean devices" (plus OpenNI's
//! extended error) when no device can be opened, InputError naming the file for a missing or
//! unreadable .oni / recording folder. next() returns kOk, kTimeout, kEndOfStream (files, once
//! the last frame was delivered; again on every later call), kDisconnected (disconnect callback
//! or `disconnect_timeouts` consecutive timeouts on a live device) or kError (last_error()).
//! Frames: index = OpenNI frame index (renumbered 1..N by the .oni player), device_ts_us =
//! OpenNI timestamp (µs; rebased to 0 by the .oni player), host_ts_ns = steady clock, depth
//! copied (0 = invalid), depth_unit_m 0.001 or 0.0001, K from the stream FOV (OpenNI's pinhole).
//! Not thread-safe: use one source from one thread. The factory does not open the source.
std::unique_ptr<RangeSource> make_openni2_source(const std::string& uri,
                                                 const OpenNI2Options& options = {});

//! A source that records depth from a live or virtual device (`device_uri` as for
//! make_openni2_source, e.g. "openni2://", "vsensor://...") to `out_oni` with openni::Recorder
//! (lossless) while it is read: open() opens the device, checks and creates the file, starts the
//! recorder ~100 ms before the stream so the first frames are kept; next() delivers the frames
//! (no disconnect by timeouts: the recording ends on the disconnect callback or at the end of
//! the data); close() (or destruction) stops the recorder. It cannot reconnect (open() a second
//! time throws UnavailableError). Read it with acquire() (pipeline/acquisition.h), which holds
//! the stop rules. The .oni is written in place by OpenNI (not atomically). Measured with
//! Debian's libOniFile: a recorder killed with SIGKILL leaves a file without a frame count that
//! still plays back, bit-exact, up to its last written frame (make_openni2_source then reports
//! an unknown frame_count); the recording folder format (replay module) remains the crash-safe
//! capture path with a documented guarantee. \throw OptionError (a URI that is not openni2:// or
//! vsensor://); open() throws UnavailableError and IoError (the file cannot be created; checked
//! before OpenNI touches it).
std::unique_ptr<RangeSource> make_oni_recording_source(const std::string& device_uri,
                                                       const std::filesystem::path& out_oni);

//! One device as OpenNI2 lists it.
struct OpenNI2DeviceEntry {
  std::string uri, vendor, name;
  std::uint16_t usb_vendor_id = 0, usb_product_id = 0;
};

//! OpenNI2's device list (OpenNI::enumerateDevices) with the driver folder in use.
struct OpenNI2DeviceList {
  bool initialized = false;          //!< OpenNI::initialize succeeded
  std::string error;                 //!< OpenNI's extended error when it did not
  std::string driver_folder;         //!< where libOpenNI2 looked for drivers
  std::vector<std::string> drivers;  //!< lib*.so.0 files found there
  std::vector<OpenNI2DeviceEntry> devices;
};

//! Lists the devices OpenNI2 sees now (initializes OpenNI2 if needed; never throws for "no
//! devices"). Thread-safe with respect to other sources only through the shared context.
OpenNI2DeviceList list_openni2_devices();

}  // namespace scanclean

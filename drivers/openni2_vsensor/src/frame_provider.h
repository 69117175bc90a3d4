#pragma once
//! \file frame_provider.h
//! Where the virtual sensor's frames come from, independent of the OpenNI2 driver protocol:
//! a recording folder (format v1, read with the replay module's RecordingReader) or a generated,
//! bit-exact test pattern. Also parses the vsensor:// URI. Private to the plugin.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "scanclean/core/range_frame.h"

namespace scanclean::vsensor {

//! Parsed form of
//!   vsensor://<abs recording folder>?pace=manual|realtime&loop=0|1&drop=<list>|every<N>
//!                                   &disconnect_after=<N>
//!   vsensor://pattern?w=<W>&h=<H>&n=<frames>&fps=<F>&unit=mm|100um (+ the options above)
//!   vsensor://default   (the pattern, 640x480; announced only when VSENSOR_ANNOUNCE=1)
//! drop=2,5 drops the frames at those 0-based positions of the folder; drop=every3 drops every
//! third frame (positions 2, 5, 8, ...). disconnect_after=N announces a disconnect after N frames
//! were delivered (0 = never).
struct VsensorUri {
  std::string uri;     //!< the full URI as given
  std::string folder;  //!< recording folder ("" for the pattern)
  bool pattern = false;
  bool realtime = false;  //!< pace=realtime (default manual: one frame per waitForAnyStream)
  bool loop = false;
  std::set<std::size_t> drop_positions;
  std::size_t drop_every = 0;
  std::size_t disconnect_after = 0;
  int pattern_width = 640, pattern_height = 480, pattern_fps = 30;
  std::size_t pattern_frames = 300;
  bool pattern_100um = false;

  bool dropped(std::size_t position) const {
    return drop_positions.count(position) != 0 ||
           (drop_every > 0 && (position + 1) % drop_every == 0);
  }
};

//! Parses a vsensor:// URI. \throw std::invalid_argument with a message naming the parameter.
VsensorUri parse_vsensor_uri(const std::string& uri);

//! The value the test pattern has at pixel (u, v) of the frame at `position` (0 = invalid).
//! Tests recompute it to check frames bit for bit.
std::uint16_t pattern_value(int u, int v, std::size_t position);

struct ProvidedFrame {
  std::uint64_t index = 0;
  std::int64_t device_ts_us = 0;
  std::vector<std::uint16_t> depth;  //!< width*height, row-major
};

class FrameProvider {
 public:
  virtual ~FrameProvider() = default;
  virtual int width() const = 0;
  virtual int height() const = 0;
  virtual double unit_m() const = 0;
  virtual double hfov_rad() const = 0;
  virtual double vfov_rad() const = 0;
  virtual int fps() const = 0;
  virtual std::size_t frame_count() const = 0;
  //! Frame at 0-based position i < frame_count(). \throw std::exception on unreadable data.
  virtual ProvidedFrame frame(std::size_t i) const = 0;
  //! Index and timestamp of frame i without decoding it (depth left empty).
  virtual ProvidedFrame stamp(std::size_t i) const = 0;
  virtual std::optional<Ps1080Params> ps1080() const { return std::nullopt; }
  virtual std::string serial() const { return {}; }
  virtual std::string device_name() const { return "Virtual Sensor"; }
};

//! Opens the provider for a parsed URI. \throw std::exception (InputError for bad recordings).
std::unique_ptr<FrameProvider> make_frame_provider(const VsensorUri& uri);

}  // namespace scanclean::vsensor

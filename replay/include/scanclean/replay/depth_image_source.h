#pragma once
//! \file depth_image_source.h
//! Public depth-image formats as a RangeSource (one file = one frame, a folder = a sequence).
//! Encodings (all 16-bit, 0 = invalid; recordings/README.md "Depth images" has the details):
//!  - "tum": 16-bit PNG, metres = value / 5000 (TUM RGB-D benchmark); kept as is, unit 0.0002 m.
//!  - "mm":  16-bit PNG, 16-bit TIFF or standard big-endian 16-bit PGM, millimetres (Redwood,
//!           slambook, PCL ImageGrabber TIFF); unit 0.001 m.
//!  - "nyu": NYU Depth v2 raw Kinect disparity in a PGM whose samples are little-endian despite
//!           the header; depth_m = 351.3 / (1092.5 - raw), raw 2047 = invalid; converted to
//!           millimetres (unit 0.001 m; 0.1 mm units would overflow 16 bits beyond 6.55 m).
//!  - "auto": decided once per source from the first image, and stated in SourceInfo::name.
//! Intrinsics come from DepthImageOptions::K (the command line) or a sidecar file
//! `intrinsics.json` beside the images (or in their parent folder); see recordings/README.md.

#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "scanclean/core/range_source.h"

namespace scanclean {

struct DepthImageOptions {
  std::string format = "auto";  //!< "auto", "tum", "mm" or "nyu"
  //! Intrinsics from the command line (--fx --fy --cx --cy); width/height 0 = the image size.
  //! Overrides the sidecar.
  std::optional<Intrinsics> K;
  //! "" = by format ("nguyen2012" for tum and nyu, both Kinect v1; "none" for mm) unless the
  //! sidecar names one; else "nguyen2012", "structured-light" or "none".
  std::string noise_model;
  //! Frame spacing (seconds) for timestamps when file names carry none; > 0.
  double frame_period_s = 1.0 / 30.0;
};

//! \throw OptionError naming the option, the value and the valid values.
void validate(const DepthImageOptions& options);

//! The depth images a folder holds, in numeric-aware name order ("2.pgm" before "10.pgm"):
//! extensions .png .pgm .tif .tiff (any case); names containing "rgb", "color" or "colour" are
//! skipped. A folder without such images but with a "depth" subfolder uses that subfolder.
//! A file is returned alone. \throw InputError when the path is missing or holds no depth image.
std::vector<std::filesystem::path> list_depth_images(const std::filesystem::path& file_or_folder);

//! Microseconds since the epoch from a file name's stem: a TUM name ("1305031102.160407",
//! seconds) or a PCL grabber name ("frame_20121214T142255.814212_depth", UTC); nothing else.
std::optional<std::int64_t> timestamp_from_name(const std::string& stem);

//! Numeric-aware "natural" order of file names: digit runs compare as numbers.
bool natural_less(const std::string& a, const std::string& b);

//! A finite source over depth images. The factory validates the options and lists the files
//! (\throw OptionError, InputError); open() resolves the intrinsics (\throw OptionError saying
//! how to pass --fx --fy --cx --cy or the sidecar when there are none) and decodes the first
//! image to decide the format; next() decodes one image per call (\throw InputError naming the
//! file for a wrong bit depth, channel count, size or truncated data) and returns kEndOfStream
//! after the last, again on every later call. Frame index = position in the sequence;
//! device_ts_us from TUM-style names ("1305031102.160407.png", seconds) or PCL grabber names
//! ("frame_20121214T142255.814212_depth.tiff", UTC) when every name has one and they increase,
//! else index * frame_period_s; host_ts_ns = device_ts_us * 1000. info().kind "depth-images".
std::unique_ptr<RangeSource> make_depth_image_source(const std::filesystem::path& file_or_folder,
                                                     const DepthImageOptions& options = {});

}  // namespace scanclean

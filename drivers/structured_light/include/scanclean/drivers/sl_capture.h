#pragma once
//! \file sl_capture.h
//! A structured-light capture folder: the camera images of one Gray-code sequence.
//!
//! Layout "scanclean" (recordings/README.md, "Structured-light captures"):
//!   capture.json   {"format":"scanclean-sl/1", "projector":{"width":W,"height":H},
//!                   "pattern":"graycode", "order":"opencv", "count":N (Gray-code images),
//!                   "white_index":N, "black_index":N+1, "images":"img/%03d.png",
//!                   "thresholds":{"white":5,"black":40}, optional "exposure_us", "camera_serial"}
//!   img/000.png .. img/NNN.png   camera images (lossless 8- or 16-bit grayscale), index k taken
//!                   while the projector showed pattern k of GrayCodePattern::generate() (column
//!                   bits MSB first, then row bits, each pattern followed by its inverse), then
//!                   white and black (getImagesForShadowMasks)
//!   calib.yml      calibration (sl_calibration.h), here or in the parent folder
//! Layout "kamino410" (kamino410/procam-calibration sample data): graycode_00.png ..
//!   graycode_NN.png (N-1 Gray-code images in OpenCV order, then white, then black) and
//!   calibration_result.xml here or in the parent folder; the projector size comes from the
//!   options or from ../graycode_pattern/pattern_00.png.

#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "scanclean/core/image.h"

namespace scanclean {

//! The Gray-code pattern set OpenCV generates for a projector size.
struct GrayCodeLayout {
  int projector_width = 0;
  int projector_height = 0;
  int column_bits = 0;  //!< ceil(log2(width))
  int row_bits = 0;     //!< ceil(log2(height))
  int pattern_count() const { return 2 * (column_bits + row_bits); }
};

//! The layout for a projector size, cross-checked with OpenCV's GrayCodePattern.
//! \throw OptionError for sizes outside 2..65535.
GrayCodeLayout graycode_layout(int projector_width, int projector_height);

//! What a capture folder holds (read from capture.json or detected), before loading images.
struct SlCaptureInfo {
  std::filesystem::path folder;
  std::string layout;  //!< "scanclean" or "kamino410"
  GrayCodeLayout graycode;
  int white_index = 0;
  int black_index = 0;
  int white_threshold = 5;                    //!< from capture.json (or the default)
  int black_threshold = 40;                   //!< from capture.json (or the default)
  std::vector<std::filesystem::path> images;  //!< every image, by index
  std::filesystem::path calibration;          //!< found calibration file, empty if none
  std::optional<double> exposure_us;
  std::string camera_serial;
};

//! True when `path` is a folder with capture.json or the kamino410 layout (graycode_00.png).
bool is_structured_light_capture(const std::filesystem::path& path);

//! Capture folders under `path`: {path} if it is a capture, else its sub-folders that are
//! captures, sorted by name (a session of several captures sharing one calibration).
std::vector<std::filesystem::path> find_structured_light_captures(
    const std::filesystem::path& path);

//! Parses the text of a capture.json (`file` names it in messages; its folder is the capture
//! folder). Checks every item (types, integer ranges, the image count against the projector
//! size, finite numbers) without touching the disk; `calibration` is left empty.
//! \throw InputError naming the file and the item.
SlCaptureInfo parse_sl_capture_description(std::string_view text, const std::filesystem::path& file,
                                           int projector_width = 0, int projector_height = 0);

//! Reads capture.json or detects the kamino410 layout. projector_width/height override (and for
//! kamino410 supply) the projector size when > 0.
//! \throw InputError naming the file and the missing or inconsistent item.
SlCaptureInfo describe_sl_capture(const std::filesystem::path& folder, int projector_width = 0,
                                  int projector_height = 0);

//! The loaded images of one capture (8- or 16-bit grayscale, all the same size). Cheap to copy
//! (shared, immutable pixel data). OpenCV stays inside the implementation.
class SlCapture {
 public:
  SlCapture();
  //! Loads every image listed by `info`. \throw InputError naming the image file that is
  //! missing, unreadable, of another size or another bit depth than the first one.
  static SlCapture load(const SlCaptureInfo& info);
  //! An in-memory capture (tests): images in `info` order (patterns, then the white and black
  //! indices). \throw InputError on count or size mismatch.
  static SlCapture from_images(const SlCaptureInfo& info,
                               const std::vector<Image<std::uint8_t>>& images);

  const SlCaptureInfo& info() const;
  int width() const;
  int height() const;
  int bit_depth() const;  //!< 8 or 16

  struct Impl;
  const Impl& impl() const { return *impl_; }

 private:
  std::shared_ptr<const Impl> impl_;
};

//! Writes the projector images of the Gray-code sequence for a projector size into
//! `folder`/patterns/000.png .. (the patterns, then white, then black, as lossless 8-bit PNG) and
//! `folder`/capture.json describing them (thresholds as given). Returns the number of images.
//! \throw OptionError for a bad size, IoError when a file cannot be written.
int write_graycode_patterns(const std::filesystem::path& folder, int projector_width,
                            int projector_height, int white_threshold = 5,
                            int black_threshold = 40);

}  // namespace scanclean

#pragma once
//! \file sl_decode.h
//! Gray-code decoding: per camera pixel the projector column and row, a validity status and a
//! confidence (docs/SENSORS.md §5).
//!
//! A pixel is valid when
//!  - it is lit: white - black > black_threshold (the shadow mask of OpenCV's decode(), signed),
//!  - every bit is readable: |I_k - I_inv_k| >= white_threshold (as GrayCodePattern::getProjPixel),
//!  - the decoded column < projector width and row < projector height.
//! Bit k is 1 when I_k > I_inv_k (ties read 0, as OpenCV). Confidence of a valid pixel:
//! c = min_k |I_k - I_inv_k| / (white - black), clamped to [0, 1]; 0 for invalid pixels.
//!
//! Sub-stripe decoding (on by default, SlDecodeOptions::sub_stripe): the integer code of each
//! axis, truncated to the Gray-code bits at and above `sub_stripe_level`, changes by one at the
//! stripe edges. Along every camera row and every camera column each such edge is located where
//! the flipping bit's pattern and inverse intensities cross: linear interpolation of
//! (I - I_inv) / (white - black) between the two pixels around its sign change (the division
//! removes the printed albedo's change from pixel to pixel). Runs of up to 3 weak-bit pixels
//! (pattern and inverse too close: typically right on a fine stripe edge) do not break a scan
//! line; invalid pixels of other kinds and jumps of the code do. A valid pixel between two edges
//! gets the projector coordinate interpolated linearly between the edges' coordinates (the
//! stripe boundary (j + 1) 2^level - 0.5); the row and column scans are averaged (weights
//! 1 / edge spacing). The integer decode (column, row, status, valid) is unchanged. The
//! confidence of a valid pixel is then multiplied by
//!  - 0.5 for each axis that no pair of edges brackets (that axis keeps the integer code),
//!  - 1 / (1 + (g / 0.25)^2) with g = |grad white| / white (central differences): mixed pixels
//!    at printed texture edges,
//!  - exp(-(e / 0.5 stripe)^2) per axis, e = the disagreement of the row and column scans.

#include <cstddef>
#include <cstdint>
#include <string>

#include "scanclean/core/image.h"
#include "scanclean/drivers/sl_capture.h"

namespace scanclean {

enum class SlDecoder {
  kFast,    //!< the project's vectorised decoder (whole-image passes per bit, Gray -> binary)
  kOpenCV,  //!< cv::structured_light::GrayCodePattern::getProjPixel per pixel (8-bit only)
};

//! "fast" / "opencv"; parse_sl_decoder throws OptionError for anything else.
const char* to_string(SlDecoder decoder);
SlDecoder parse_sl_decoder(const std::string& name);

struct SlDecodeOptions {
  int white_threshold = 5;   //!< gray levels (of the image bit depth), >= 0
  int black_threshold = 40;  //!< gray levels, >= 0
  SlDecoder decoder = SlDecoder::kFast;
  int threads = 0;         //!< fast decoder: 0 = all cores; the result is identical for any value
  bool sub_stripe = true;  //!< sub-stripe projector coordinates (column_f, row_f)
  //! Finest Gray-code bit whose edges are used (0 = every code step), 0..8; the edges of finer
  //! bits are skipped (for cameras that do not resolve them).
  int sub_stripe_level = 0;
  //! Largest edge spacing interpolated across (camera pixels), > 1.
  double sub_stripe_max_span_px = 40;
};
//! \throw OptionError naming the option, the value and the valid range.
void validate(const SlDecodeOptions& options);

//! Per-pixel outcome.
enum class SlPixelStatus : std::uint8_t {
  kValid = 0,
  kShadow = 1,      //!< white - black <= black_threshold
  kWeakBit = 2,     //!< some |I_k - I_inv_k| < white_threshold
  kOutOfRange = 3,  //!< decoded column >= width or row >= height
};

struct SlDecoded {
  Image<std::int32_t> column;  //!< projector column, -1 where not valid
  Image<std::int32_t> row;     //!< projector row, -1 where not valid
  //! Sub-stripe projector column / row (decoded Gray-code pixel units, pixel centres at
  //! integers; NaN where not valid). Empty images when sub-stripe decoding is off.
  Image<float> column_f;
  Image<float> row_f;
  std::size_t sub_stripe_pixels = 0;  //!< valid pixels bracketed by edges on both axes
  Image<float> confidence;            //!< [0, 1], 0 where not valid
  Image<std::uint8_t> status;         //!< SlPixelStatus values
  std::size_t valid = 0;              //!< pixels with status kValid
  std::size_t lit = 0;                //!< pixels that are not kShadow
  double seconds = 0;                 //!< decoding time (wall clock, images already in memory)
  SlDecoder decoder = SlDecoder::kFast;
};

//! Decodes a loaded capture. The OpenCV decoder needs 8-bit images (it reads them as uchar).
//! \throw OptionError (bad options, OpenCV decoder on 16-bit images).
SlDecoded decode_graycode(const SlCapture& capture, const SlDecodeOptions& options = {});

}  // namespace scanclean

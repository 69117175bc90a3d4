#pragma once
//! \file png16.h (private to scanclean::replay)
//! 16-bit single-channel PNG input and output through OpenCV's imgcodecs, with the PNG header
//! checked before decoding (no allocation from a lying header, clear errors naming the file).

#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "scanclean/core/image.h"

namespace scanclean::detail {

//! Whole file contents; refuses files larger than max_bytes. \throw InputError (missing, too
//! large), IoError (read failure).
std::vector<unsigned char> read_file_bytes(const std::filesystem::path& file,
                                           std::uintmax_t max_bytes);

struct PngHeader {
  std::uint32_t width = 0, height = 0;
  int bit_depth = 0;   //!< 1, 2, 4, 8 or 16
  int color_type = 0;  //!< 0 gray, 2 RGB, 3 palette, 4 gray+alpha, 6 RGBA
};
//! Parses the signature and IHDR chunk. \throw InputError naming the file and byte offset.
PngHeader parse_png_header(const std::vector<unsigned char>& bytes, const std::string& file);
//! Human-readable "16-bit grayscale", "8-bit RGB", ...
std::string describe_png(const PngHeader& h);

//! Reads a 16-bit grayscale PNG of exactly width x height (0 = any size up to 2^26 pixels).
//! `role` ("depth", "confidence") appears in messages. \throw InputError naming the file.
Image<std::uint16_t> read_png16(const std::filesystem::path& file, int width, int height,
                                const std::string& role);

//! Encodes a 16-bit grayscale PNG (lossless) and writes it atomically (temporary file, fsync,
//! rename). \throw IoError.
void write_png16_atomically(const std::filesystem::path& file, const Image<std::uint16_t>& image);

//! 8-bit RGB PNG (lossless), written atomically. \throw IoError.
void write_rgb_png_atomically(const std::filesystem::path& file,
                              const Image<std::array<std::uint8_t, 3>>& rgb);

//! Width and height from the first IFD of a classic TIFF (tags 256 and 257), read before OpenCV
//! decodes, so that a lying header cannot make it allocate a huge image; nothing when the
//! structure is not understood.
std::optional<std::pair<std::uint64_t, std::uint64_t>> tiff_size(
    const std::vector<unsigned char>& bytes);

//! Any 8-bit PNG, JPEG, PPM or TIFF (gray, RGB, RGBA) as RGB, at most 2^26 pixels. \throw
//! InputError.
Image<std::array<std::uint8_t, 3>> read_rgb_image(const std::filesystem::path& file);

}  // namespace scanclean::detail

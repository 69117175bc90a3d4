#include "png16.h"

#include <algorithm>
#include <cctype>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <system_error>

#include "scanclean/core/atomic_file.h"
#include "scanclean/core/errors.h"

namespace scanclean::detail {

namespace {
constexpr unsigned char kSignature[8] = {0x89, 'P', 'N', 'G', 0x0D, 0x0A, 0x1A, 0x0A};
constexpr std::uint64_t kMaxPixels = std::uint64_t{1} << 26;

std::uint32_t be32(const unsigned char* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) |
         std::uint32_t{p[3]};
}
}  // namespace

std::vector<unsigned char> read_file_bytes(const std::filesystem::path& file,
                                           std::uintmax_t max_bytes) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(file, ec))
    throw InputError(file.string(), "", "missing (or not a regular file)");
  const std::uintmax_t size = std::filesystem::file_size(file, ec);
  if (ec) throw IoError(file.string() + ": cannot stat: " + ec.message());
  if (size > max_bytes)
    throw InputError(file.string(), "",
                     "file of " + std::to_string(size) + " bytes is larger than the limit of " +
                         std::to_string(max_bytes) + " bytes");
  std::vector<unsigned char> bytes(static_cast<std::size_t>(size));
  std::ifstream in(file, std::ios::binary);
  if (!in) throw IoError(file.string() + ": cannot open for reading");
  if (size > 0 &&
      !in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(size)))
    throw IoError(file.string() + ": read failed after " + std::to_string(in.gcount()) + " bytes");
  return bytes;
}

PngHeader parse_png_header(const std::vector<unsigned char>& bytes, const std::string& file) {
  if (bytes.size() < 33)
    throw InputError(file, byte_place(bytes.size()),
                     "truncated PNG: " + std::to_string(bytes.size()) +
                         " bytes, a PNG needs at least 33 for its signature and header");
  for (int i = 0; i < 8; ++i)
    if (bytes[i] != kSignature[i])
      throw InputError(file, byte_place(static_cast<std::uint64_t>(i)),
                       "not a PNG file (bad signature)");
  if (be32(&bytes[8]) != 13 || std::string(bytes.begin() + 12, bytes.begin() + 16) != "IHDR")
    throw InputError(file, byte_place(8), "PNG without an IHDR chunk first");
  PngHeader h;
  h.width = be32(&bytes[16]);
  h.height = be32(&bytes[20]);
  h.bit_depth = bytes[24];
  h.color_type = bytes[25];
  return h;
}

std::string describe_png(const PngHeader& h) {
  std::string kind;
  switch (h.color_type) {
    case 0:
      kind = "grayscale";
      break;
    case 2:
      kind = "RGB";
      break;
    case 3:
      kind = "palette";
      break;
    case 4:
      kind = "grayscale+alpha";
      break;
    case 6:
      kind = "RGBA";
      break;
    default:
      kind = "colour type " + std::to_string(h.color_type);
  }
  return std::to_string(h.bit_depth) + "-bit " + kind;
}

Image<std::uint16_t> read_png16(const std::filesystem::path& file, int width, int height,
                                const std::string& role) {
  const std::string name = file.string();
  // A 16-bit PNG never exceeds raw size much; 2^26 px * 2 bytes plus slack bounds the read.
  std::uintmax_t max_bytes = (width > 0 && height > 0)
                                 ? std::uintmax_t{2} * width * height + (1u << 20)
                                 : std::uintmax_t{2} * kMaxPixels + (1u << 20);
  // Worst-case PNG expansion is small; allow 2x raw for incompressible noise.
  max_bytes *= 2;
  const std::vector<unsigned char> bytes = read_file_bytes(file, max_bytes);
  const PngHeader h = parse_png_header(bytes, name);
  if (h.bit_depth != 16 || h.color_type != 0)
    throw InputError(name, "PNG header",
                     role + " image must be a 16-bit grayscale PNG, got " + describe_png(h));
  if (width > 0 && height > 0 &&
      (h.width != static_cast<std::uint32_t>(width) ||
       h.height != static_cast<std::uint32_t>(height)))
    throw InputError(name, "PNG header",
                     role + " image is " + std::to_string(h.width) + "x" +
                         std::to_string(h.height) + ", expected " + std::to_string(width) + "x" +
                         std::to_string(height) + " (the size in session.json)");
  if (h.width == 0 || h.height == 0 || std::uint64_t{h.width} * h.height > kMaxPixels)
    throw InputError(
        name, "PNG header",
        "implausible image size " + std::to_string(h.width) + "x" + std::to_string(h.height));
  // zlib cannot compress better than about 1032:1, so a file far smaller than raw/1032 bytes
  // lies about its size: refuse it before the decoder allocates the raw image.
  const std::uint64_t raw_bytes = (std::uint64_t{h.width} * 2 + 1) * h.height;
  if (static_cast<std::uint64_t>(bytes.size()) * 1100 < raw_bytes)
    throw InputError(name, "PNG header",
                     "claims " + std::to_string(h.width) + "x" + std::to_string(h.height) +
                         " pixels, far more than " + std::to_string(bytes.size()) +
                         " bytes of PNG can hold (truncated or corrupt file)");
  cv::Mat mat;
  try {
    mat = cv::imdecode(bytes, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    throw InputError(name, "", "cannot decode PNG: " + e.msg);
  }
  if (mat.empty()) throw InputError(name, "", "cannot decode PNG (corrupt or truncated data)");
  if (mat.type() != CV_16UC1)
    throw InputError(name, "",
                     role + " image decoded to " + std::to_string(mat.channels()) +
                         " channel(s) of " + std::to_string(mat.elemSize1() * 8) +
                         " bits, expected one 16-bit channel");
  if (mat.cols != static_cast<int>(h.width) || mat.rows != static_cast<int>(h.height))
    throw InputError(name, "", "decoded size differs from the PNG header");
  Image<std::uint16_t> out(mat.cols, mat.rows);
  for (int v = 0; v < mat.rows; ++v) {
    const auto* row = mat.ptr<std::uint16_t>(v);
    std::copy(row, row + mat.cols, out.data.begin() + static_cast<std::ptrdiff_t>(v) * mat.cols);
  }
  return out;
}

void write_png16_atomically(const std::filesystem::path& file, const Image<std::uint16_t>& image) {
  // cv::Mat header over the image's own buffer (no copy); imencode does not modify it.
  cv::Mat mat(image.height, image.width, CV_16UC1, const_cast<std::uint16_t*>(image.data.data()));
  std::vector<unsigned char> encoded;
  bool ok = false;
  try {
    // Compression level 1 with run-length matching: fast (recording keeps up with 30 fps beside
    // the cleaning), still lossless. On the 3dj frames (640 x 480) it encodes in 5.2 ms and
    // 91 KB, the default strategy in 6.0 ms and 107 KB.
    ok = cv::imencode(
        ".png", mat, encoded,
        {cv::IMWRITE_PNG_COMPRESSION, 1, cv::IMWRITE_PNG_STRATEGY, cv::IMWRITE_PNG_STRATEGY_RLE});
  } catch (const cv::Exception& e) {
    throw IoError(file.string() + ": PNG encoding failed: " + e.msg);
  }
  if (!ok) throw IoError(file.string() + ": PNG encoding failed");
  write_file_atomically(file, [&](std::ostream& out) {
    out.write(reinterpret_cast<const char*>(encoded.data()),
              static_cast<std::streamsize>(encoded.size()));
  });
}

void write_rgb_png_atomically(const std::filesystem::path& file,
                              const Image<std::array<std::uint8_t, 3>>& rgb) {
  cv::Mat bgr(rgb.height, rgb.width, CV_8UC3);
  for (int v = 0; v < rgb.height; ++v)
    for (int u = 0; u < rgb.width; ++u) {
      const auto& p = rgb(u, v);
      bgr.at<cv::Vec3b>(v, u) = cv::Vec3b(p[2], p[1], p[0]);  // OpenCV stores BGR
    }
  std::vector<unsigned char> encoded;
  bool ok = false;
  try {
    ok = cv::imencode(".png", bgr, encoded, {cv::IMWRITE_PNG_COMPRESSION, 1});
  } catch (const cv::Exception& e) {
    throw IoError(file.string() + ": PNG encoding failed: " + e.msg);
  }
  if (!ok) throw IoError(file.string() + ": PNG encoding failed");
  write_file_atomically(file, [&](std::ostream& out) {
    out.write(reinterpret_cast<const char*>(encoded.data()),
              static_cast<std::streamsize>(encoded.size()));
  });
}

namespace {

// The image size a PNG, JPEG, binary/ASCII PPM/PGM or classic TIFF declares, checked against
// the file's real size before the decoder allocates anything: a Netpbm raster must be in the
// file; a compressed one cannot expand more than deflate's / JPEG's best ratio (about 1032:1;
// 1100 allowed, also for TIFF's PackBits/LZW/deflate). Any other format is refused (the decoder
// would trust its header). The signatures are checked as strictly as OpenCV's decoders check
// them (JPEG FF D8 FF, Netpbm magic + whitespace, TIFF II*0 / MM0*): OpenCV picks the first
// decoder whose signature matches, and one that did not would let another decoder (such as
// GDCM's, which finds "DICM" at byte 128 and aborts on a malformed file) read the bytes.
void check_colour_image_size(const std::vector<unsigned char>& b, const std::string& name) {
  const std::uint64_t size = b.size();
  std::uint64_t w = 0, h = 0, raster = 0;  // raster: bytes the pixels need at least
  bool compressed = true;
  std::string kind;
  if (size >= 8 && b[0] == 0x89 && b[1] == 'P') {
    kind = "PNG";
    const PngHeader ph = parse_png_header(b, name);
    w = ph.width;
    h = ph.height;
    raster = w * h * (ph.color_type == 0 || ph.color_type == 3 ? 1 : 3);
  } else if (size >= 4 && b[0] == 0xFF && b[1] == 0xD8 && b[2] == 0xFF) {
    kind = "JPEG";
    std::size_t i = 2;
    while (i + 9 < size) {
      if (b[i] != 0xFF) throw InputError(name, byte_place(i), "corrupt JPEG: expected a marker");
      const unsigned m = b[i + 1];
      if (m == 0xFF) {
        ++i;
        continue;
      }
      const std::size_t len = (std::size_t{b[i + 2]} << 8) | b[i + 3];
      if (m >= 0xC0 && m <= 0xCF && m != 0xC4 && m != 0xC8 && m != 0xCC) {
        h = (std::uint64_t{b[i + 5]} << 8) | b[i + 6];
        w = (std::uint64_t{b[i + 7]} << 8) | b[i + 8];
        break;
      }
      if (len < 2) throw InputError(name, byte_place(i), "corrupt JPEG: segment length < 2");
      i += 2 + len;
    }
    if (w == 0 || h == 0)
      throw InputError(name, "", "JPEG without a frame header (SOF) giving its size");
    raster = w * h;
  } else if (size >= 3 && b[0] == 'P' &&
             (b[1] == '2' || b[1] == '3' || b[1] == '5' || b[1] == '6') && std::isspace(b[2])) {
    kind = "PPM/PGM";
    compressed = false;
    // "P6 <w> <h> <maxval>" with whitespace and # comments; then one whitespace byte.
    std::size_t i = 2;
    std::uint64_t v[3] = {0, 0, 0};
    for (int k = 0; k < 3; ++k) {
      for (;;) {
        while (i < size && std::isspace(b[i])) ++i;
        if (i < size && b[i] == '#') {
          while (i < size && b[i] != '\n') ++i;
          continue;
        }
        break;
      }
      std::size_t digits = 0;
      while (i < size && b[i] >= '0' && b[i] <= '9' && digits < 10) {
        v[k] = v[k] * 10 + (b[i] - '0');
        ++i;
        ++digits;
      }
      if (digits == 0 || digits == 10)
        throw InputError(name, byte_place(i), "corrupt PPM/PGM header: expected a size");
    }
    w = v[0];
    h = v[1];
    if (v[2] == 0 || v[2] > 65535)
      throw InputError(name, "header",
                       "PPM/PGM maximum value " + std::to_string(v[2]) + " out of range 1..65535");
    const std::uint64_t channels = (b[1] == '3' || b[1] == '6') ? 3 : 1;
    const bool ascii = b[1] == '2' || b[1] == '3';
    const std::uint64_t sample = ascii ? 2 : (v[2] > 255 ? 2 : 1);  // ASCII: digit + space
    raster = w * h * channels * sample;
    if (raster > size - std::min<std::uint64_t>(size, i + 1))
      throw InputError(name, "header",
                       std::to_string(w) + "x" + std::to_string(h) + " " +
                           (channels == 3 ? "colour" : "gray") + " pixels need at least " +
                           std::to_string(raster) + " bytes, but the file has " +
                           std::to_string(size) + " (truncated file or wrong size)");
  } else if (size >= 4 && ((b[0] == 'I' && b[1] == 'I') || (b[0] == 'M' && b[1] == 'M'))) {
    kind = "TIFF";
    const auto wh = tiff_size(b);
    if (!wh)
      throw InputError(name, "TIFF header",
                       "no image width and height found (not a classic TIFF, or corrupt)");
    w = wh->first;
    h = wh->second;
    raster = w * h * 3;
  } else {
    throw InputError(name, "", "not a PNG, JPEG, PPM/PGM or TIFF colour image");
  }
  if (w == 0 || h == 0 || w * h > kMaxPixels)
    throw InputError(name, kind + " header",
                     "implausible image size " + std::to_string(w) + "x" + std::to_string(h) +
                         " (at most 2^26 pixels)");
  if (compressed && raster > 1100 * size)
    throw InputError(name, kind + " header",
                     std::to_string(w) + "x" + std::to_string(h) +
                         " pixels cannot be compressed into " + std::to_string(size) +
                         " bytes (truncated file or a lying header)");
}

}  // namespace

std::optional<std::pair<std::uint64_t, std::uint64_t>> tiff_size(
    const std::vector<unsigned char>& b) {
  if (b.size() < 8) return std::nullopt;
  bool le;
  if (b[0] == 'I' && b[1] == 'I')
    le = true;
  else if (b[0] == 'M' && b[1] == 'M')
    le = false;
  else
    return std::nullopt;
  auto u16 = [&](std::size_t o) -> std::uint32_t {
    return le ? (b[o] | (b[o + 1] << 8)) : ((b[o] << 8) | b[o + 1]);
  };
  auto u32 = [&](std::size_t o) -> std::uint32_t {
    return le ? (std::uint32_t{b[o]} | (std::uint32_t{b[o + 1]} << 8) |
                 (std::uint32_t{b[o + 2]} << 16) | (std::uint32_t{b[o + 3]} << 24))
              : ((std::uint32_t{b[o]} << 24) | (std::uint32_t{b[o + 1]} << 16) |
                 (std::uint32_t{b[o + 2]} << 8) | std::uint32_t{b[o + 3]});
  };
  if (u16(2) != 42) return std::nullopt;  // classic TIFF only (BigTIFF: left to OpenCV)
  const std::uint64_t ifd = u32(4);
  if (ifd + 2 > b.size()) return std::nullopt;
  const std::uint32_t n = u16(ifd);
  if (ifd + 2 + std::uint64_t{n} * 12 > b.size()) return std::nullopt;
  std::uint64_t w = 0, h = 0;
  for (std::uint32_t k = 0; k < n; ++k) {
    const std::size_t e = ifd + 2 + k * 12;
    const std::uint32_t tag = u16(e), type = u16(e + 2);
    if (tag != 256 && tag != 257) continue;
    const std::uint64_t v = type == 3 ? u16(e + 8) : type == 4 ? u32(e + 8) : 0;
    (tag == 256 ? w : h) = v;
  }
  if (w == 0 || h == 0) return std::nullopt;
  return std::make_pair(w, h);
}

Image<std::array<std::uint8_t, 3>> read_rgb_image(const std::filesystem::path& file) {
  const std::string name = file.string();
  const std::vector<unsigned char> bytes = read_file_bytes(file, std::uintmax_t{1} << 28);
  check_colour_image_size(bytes, name);
  cv::Mat mat;
  try {
    mat = cv::imdecode(bytes, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    throw InputError(name, "", "cannot decode the colour image: " + e.msg);
  }
  if (mat.empty()) throw InputError(name, "", "cannot decode the colour image (corrupt?)");
  if (mat.depth() != CV_8U)
    throw InputError(name, "",
                     "colour image must have 8-bit channels, got " +
                         std::to_string(mat.elemSize1() * 8) + "-bit");
  cv::Mat bgr;
  if (mat.channels() == 1)
    cv::merge(std::vector<cv::Mat>{mat, mat, mat}, bgr);
  else if (mat.channels() == 3)
    bgr = mat;
  else if (mat.channels() == 4) {  // BGRA: drop alpha
    std::vector<cv::Mat> ch;
    cv::split(mat, ch);
    cv::merge(std::vector<cv::Mat>{ch[0], ch[1], ch[2]}, bgr);
  } else
    throw InputError(name, "", "colour image has " + std::to_string(mat.channels()) + " channels");
  Image<std::array<std::uint8_t, 3>> out(bgr.cols, bgr.rows);
  for (int v = 0; v < bgr.rows; ++v)
    for (int u = 0; u < bgr.cols; ++u) {
      const cv::Vec3b p = bgr.at<cv::Vec3b>(v, u);
      out(u, v) = {p[2], p[1], p[0]};
    }
  return out;
}

}  // namespace scanclean::detail

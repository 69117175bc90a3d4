#include "scanclean/drivers/sl_decode.h"

#include <tbb/blocked_range.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <memory>
#include <opencv2/structured_light.hpp>
#include <type_traits>
#include <vector>

#include "scanclean/core/errors.h"
#include "sl_capture_impl.h"

namespace scanclean {
namespace {

SlDecoded make_output(int w, int h, SlDecoder decoder) {
  SlDecoded d;
  d.column = Image<std::int32_t>(w, h, -1);
  d.row = Image<std::int32_t>(w, h, -1);
  d.confidence = Image<float>(w, h, 0.0f);
  d.status = Image<std::uint8_t>(w, h, static_cast<std::uint8_t>(SlPixelStatus::kShadow));
  d.decoder = decoder;
  return d;
}

void count(SlDecoded& d) {
  d.valid = 0;
  d.lit = 0;
  for (std::uint8_t s : d.status.data) {
    d.valid += s == static_cast<std::uint8_t>(SlPixelStatus::kValid);
    d.lit += s != static_cast<std::uint8_t>(SlPixelStatus::kShadow);
  }
}

// One image row through every bit: whole-row passes per bit (d = I - I_inv, Gray bit = d > 0,
// binary bit = previous binary bit XOR Gray bit, value = value * 2 + binary bit, margin =
// min |d|). The inner loops are branch-free over contiguous arrays, so the compiler vectorises
// them.
template <class Pixel>
struct RowDecoder {
  // 16-bit lanes throughout (8 per SSE register): value < 2^16 (at most 16 bits per axis),
  // margin <= 65535; the difference needs int16 for 8-bit and int32 for 16-bit images.
  using Diff = std::conditional_t<sizeof(Pixel) == 1, std::int16_t, std::int32_t>;
  const SlCapture::Impl& cap;
  const SlDecodeOptions& opt;
  SlDecoded& out;

  void operator()(int y, std::vector<std::uint16_t>& value, std::vector<std::uint16_t>& margin,
                  std::vector<std::uint16_t>& binary, std::vector<std::uint16_t>& column) const {
    const int w = cap.images[0].cols;
    const auto& info = cap.info;
    std::fill(margin.begin(), margin.end(), std::uint16_t{65535});
    for (int axis = 0; axis < 2; ++axis) {
      const int bits = axis == 0 ? info.graycode.column_bits : info.graycode.row_bits;
      const int first = axis == 0 ? 0 : 2 * info.graycode.column_bits;
      std::fill(value.begin(), value.end(), std::uint16_t{0});
      std::fill(binary.begin(), binary.end(), std::uint16_t{0});
      std::uint16_t* __restrict v = value.data();
      std::uint16_t* __restrict m = margin.data();
      std::uint16_t* __restrict b = binary.data();
      for (int k = 0; k < bits; ++k) {
        const Pixel* __restrict p =
            cap.images[static_cast<std::size_t>(cap.pattern_indices[first + 2 * k])]
                .template ptr<Pixel>(y);
        const Pixel* __restrict q =
            cap.images[static_cast<std::size_t>(cap.pattern_indices[first + 2 * k + 1])]
                .template ptr<Pixel>(y);
        for (int x = 0; x < w; ++x) {
          const Diff d = static_cast<Diff>(static_cast<Diff>(p[x]) - static_cast<Diff>(q[x]));
          const std::uint16_t g = d > 0;
          const std::uint16_t bit = static_cast<std::uint16_t>(b[x] ^ g);
          b[x] = bit;
          v[x] = static_cast<std::uint16_t>((v[x] << 1) | bit);
          const std::uint16_t a = static_cast<std::uint16_t>(d < 0 ? -d : d);
          m[x] = a < m[x] ? a : m[x];
        }
      }
      if (axis == 0) std::copy(value.begin(), value.end(), column.begin());
    }
    const Pixel* white =
        cap.images[static_cast<std::size_t>(info.white_index)].template ptr<Pixel>(y);
    const Pixel* black =
        cap.images[static_cast<std::size_t>(info.black_index)].template ptr<Pixel>(y);
    const std::size_t base = static_cast<std::size_t>(y) * w;
    const int pw = info.graycode.projector_width, ph = info.graycode.projector_height;
    for (int x = 0; x < w; ++x) {
      const std::int32_t contrast = static_cast<std::int32_t>(white[x]) - black[x];
      SlPixelStatus s = SlPixelStatus::kValid;
      if (contrast <= opt.black_threshold)
        s = SlPixelStatus::kShadow;
      else if (margin[x] < opt.white_threshold)
        s = SlPixelStatus::kWeakBit;
      else if (column[x] >= pw || value[x] >= ph)
        s = SlPixelStatus::kOutOfRange;
      out.status.data[base + x] = static_cast<std::uint8_t>(s);
      if (s == SlPixelStatus::kValid) {
        out.column.data[base + x] = column[x];
        out.row.data[base + x] = value[x];
        out.confidence.data[base + x] =
            std::min(1.0f, static_cast<float>(margin[x]) / static_cast<float>(contrast));
      }
    }
  }
};

template <class Pixel>
void decode_fast(const SlCapture::Impl& cap, const SlDecodeOptions& opt, SlDecoded& out) {
  const int w = cap.images[0].cols, h = cap.images[0].rows;
  auto body = [&](const tbb::blocked_range<int>& r) {
    const std::size_t n = static_cast<std::size_t>(w);
    std::vector<std::uint16_t> value(n), margin(n), column(n), binary(n);
    RowDecoder<Pixel> dec{cap, opt, out};
    for (int y = r.begin(); y < r.end(); ++y) dec(y, value, margin, binary, column);
  };
  // Rows are independent: any split gives the same result.
  const int threads = opt.threads > 0 ? opt.threads : tbb::this_task_arena::max_concurrency();
  tbb::task_arena arena(threads);
  arena.execute([&] { tbb::parallel_for(tbb::blocked_range<int>(0, h, 16), body); });
}

void decode_opencv(const SlCapture::Impl& cap, const SlDecodeOptions& opt, SlDecoded& out) {
  const auto& info = cap.info;
  const auto pattern = cv::structured_light::GrayCodePattern::create(
      info.graycode.projector_width, info.graycode.projector_height);
  pattern->setWhiteThreshold(static_cast<std::size_t>(opt.white_threshold));
  pattern->setBlackThreshold(static_cast<std::size_t>(opt.black_threshold));
  std::vector<cv::Mat> patterns;
  for (int k : cap.pattern_indices) patterns.push_back(cap.images[static_cast<std::size_t>(k)]);
  const cv::Mat& white = cap.images[static_cast<std::size_t>(info.white_index)];
  const cv::Mat& black = cap.images[static_cast<std::size_t>(info.black_index)];
  const int w = white.cols, h = white.rows;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * w + x;
      // The shadow mask of GrayCodePattern::decode (white - black > blackThreshold); like
      // decode(), getProjPixel runs only on lit pixels.
      const int contrast =
          static_cast<int>(white.at<std::uint8_t>(y, x)) - black.at<std::uint8_t>(y, x);
      if (contrast <= opt.black_threshold) continue;
      int margin = 1 << 30;
      for (std::size_t k = 0; k + 1 < patterns.size(); k += 2)
        margin = std::min(margin, std::abs(static_cast<int>(patterns[k].at<std::uint8_t>(y, x)) -
                                           patterns[k + 1].at<std::uint8_t>(y, x)));
      cv::Point proj;
      const bool error = pattern->getProjPixel(patterns, x, y, proj);  // true = error
      if (error) {
        out.status.data[i] = static_cast<std::uint8_t>(
            margin < opt.white_threshold ? SlPixelStatus::kWeakBit : SlPixelStatus::kOutOfRange);
        continue;
      }
      out.status.data[i] = static_cast<std::uint8_t>(SlPixelStatus::kValid);
      out.column.data[i] = proj.x;
      out.row.data[i] = proj.y;
      out.confidence.data[i] =
          std::min(1.0f, static_cast<float>(margin) / static_cast<float>(contrast));
    }
  }
}

}  // namespace

const char* to_string(SlDecoder decoder) {
  return decoder == SlDecoder::kOpenCV ? "opencv" : "fast";
}

SlDecoder parse_sl_decoder(const std::string& name) {
  if (name == "fast") return SlDecoder::kFast;
  if (name == "opencv") return SlDecoder::kOpenCV;
  throw OptionError("decoder: expected 'fast' or 'opencv', got '" + name + "'");
}

void validate(const SlDecodeOptions& o) {
  if (o.white_threshold < 0 || o.white_threshold > 65535)
    throw OptionError("white threshold: " + std::to_string(o.white_threshold) +
                      " out of range 0..65535 (gray levels)");
  if (o.black_threshold < 0 || o.black_threshold > 65535)
    throw OptionError("black threshold: " + std::to_string(o.black_threshold) +
                      " out of range 0..65535 (gray levels)");
  if (o.threads < 0 || o.threads > 1024)
    throw OptionError("threads: " + std::to_string(o.threads) + " out of range 0..1024");
}

SlDecoded decode_graycode(const SlCapture& capture, const SlDecodeOptions& options) {
  validate(options);
  const auto& cap = capture.impl();
  if (cap.images.empty()) throw OptionError("decode_graycode: empty capture");
  const auto start = std::chrono::steady_clock::now();
  SlDecoded out = make_output(capture.width(), capture.height(), options.decoder);
  if (options.decoder == SlDecoder::kOpenCV) {
    if (capture.bit_depth() != 8)
      throw OptionError(
          "decoder opencv: GrayCodePattern::getProjPixel reads 8-bit images; this "
          "capture is 16-bit (use --decoder fast)");
    decode_opencv(cap, options, out);
  } else if (capture.bit_depth() == 8) {
    decode_fast<std::uint8_t>(cap, options, out);
  } else {
    decode_fast<std::uint16_t>(cap, options, out);
  }
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  count(out);
  return out;
}

}  // namespace scanclean

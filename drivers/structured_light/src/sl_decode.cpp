#include "scanclean/drivers/sl_decode.h"

#include <tbb/blocked_range.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <limits>
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

// Sub-stripe refinement (sl_decode.h): per axis, edges of the truncated code along camera rows
// and columns, zero crossings of the flipping bit's I - I_inv, linear interpolation between
// edges.
struct SubStripeAxis {
  std::vector<float> est[2];   // per scan direction (0 = along rows, 1 = along columns)
  std::vector<float> span[2];  // edge spacing (camera px) of the estimate
};

template <class Pixel>
class SubStripe {
 public:
  SubStripe(const SlCapture::Impl& cap, const SlDecodeOptions& opt, const SlDecoded& out)
      : cap_(cap),
        opt_(opt),
        out_(out),
        white_(cap.images[static_cast<std::size_t>(cap.info.white_index)]),
        black_(cap.images[static_cast<std::size_t>(cap.info.black_index)]),
        w_(cap.images[0].cols),
        h_(cap.images[0].rows) {}

  SubStripeAxis run(int axis) const {
    SubStripeAxis r;
    const std::size_t n = static_cast<std::size_t>(w_) * static_cast<std::size_t>(h_);
    const float nan = std::numeric_limits<float>::quiet_NaN();
    for (int d = 0; d < 2; ++d) {
      r.est[d].assign(n, nan);
      r.span[d].assign(n, 0.0f);
    }
    tbb::parallel_for(tbb::blocked_range<int>(0, h_, 16), [&](const tbb::blocked_range<int>& b) {
      std::vector<Edge> edges;
      for (int y = b.begin(); y < b.end(); ++y)
        scan(axis, static_cast<std::size_t>(y) * w_, 1, w_, r.est[0], r.span[0], edges);
    });
    tbb::parallel_for(tbb::blocked_range<int>(0, w_, 16), [&](const tbb::blocked_range<int>& b) {
      std::vector<Edge> edges;
      for (int x = b.begin(); x < b.end(); ++x)
        scan(axis, static_cast<std::size_t>(x), static_cast<std::size_t>(w_), h_, r.est[1],
             r.span[1], edges);
    });
    return r;
  }

 private:
  struct Edge {
    double pos;  // along the line, pixel centres at integers
    double P;    // projector coordinate of the stripe boundary
  };

  // I - I_inv divided by the pixel's white - black contrast: the printed albedo changes from one
  // pixel to the next at texture edges, which would move the crossing of the raw difference.
  double diff(const cv::Mat& p, const cv::Mat& q, std::size_t i) const {
    const double d = static_cast<double>(reinterpret_cast<const Pixel*>(p.data)[i]) -
                     static_cast<double>(reinterpret_cast<const Pixel*>(q.data)[i]);
    const double c = static_cast<double>(reinterpret_cast<const Pixel*>(white_.data)[i]) -
                     static_cast<double>(reinterpret_cast<const Pixel*>(black_.data)[i]);
    return d / std::max(c, 1.0);
  }

  // One line of `len` pixels starting at linear index `start`, `stride` apart.
  void scan(int axis, std::size_t start, std::size_t stride, int len, std::vector<float>& est,
            std::vector<float>& span, std::vector<Edge>& edges) const {
    const auto& code = axis == 0 ? out_.column.data : out_.row.data;
    const auto& g = cap_.info.graycode;
    const int bits = axis == 0 ? g.column_bits : g.row_bits;
    const int first = axis == 0 ? 0 : 2 * g.column_bits;
    const int s = std::min(opt_.sub_stripe_level, bits - 1);
    const double width = static_cast<double>(1 << s);
    int seg_begin = 0;
    edges.clear();
    auto flush = [&](int seg_end) {  // pixels [seg_begin, seg_end] are one unbroken run
      std::size_t m = 0;
      for (int k = seg_begin; k <= seg_end && edges.size() >= 2; ++k) {
        while (m + 1 < edges.size() && edges[m + 1].pos <= k) ++m;
        if (m + 1 >= edges.size()) break;
        const Edge& l = edges[m];
        const Edge& r = edges[m + 1];
        if (l.pos > k) continue;
        const double sp = r.pos - l.pos;
        if (!(sp > 0) || sp > opt_.sub_stripe_max_span_px || l.P == r.P) continue;
        const std::size_t i = start + static_cast<std::size_t>(k) * stride;
        if (code[i] < 0) continue;
        const int t = code[i] >> s;
        if (static_cast<int>(std::floor((std::min(l.P, r.P) + 0.5) / width)) != t) continue;
        est[i] = static_cast<float>(l.P + (k - l.pos) / sp * (r.P - l.P));
        span[i] = static_cast<float>(sp);
      }
      edges.clear();
    };
    // Walk the valid pixels; a gap of up to kMaxGap weak-bit pixels (pattern and inverse too
    // close in the finest bits: typically right at a stripe edge) does not break the run.
    constexpr int kMaxGap = 3;
    const auto weak = static_cast<std::uint8_t>(SlPixelStatus::kWeakBit);
    int prev = -1;  // last valid pixel of the run
    for (int k = 0; k < len; ++k) {
      const std::size_t ik = start + static_cast<std::size_t>(k) * stride;
      if (code[ik] < 0) {
        if (out_.status.data[ik] != weak || (prev >= 0 && k - prev > kMaxGap)) {
          if (prev >= 0) flush(prev);
          prev = -1;
          seg_begin = k + 1;
        }
        continue;
      }
      if (prev < 0) {
        if (seg_begin < k) seg_begin = k;
        prev = k;
        continue;
      }
      const std::size_t ip = start + static_cast<std::size_t>(prev) * stride;
      const int t0 = code[ip] >> s, t1 = code[ik] >> s;
      if (t0 != t1) {
        if (std::abs(t1 - t0) != 1) {  // a jump: depth discontinuity or wrong bit
          flush(prev);
          seg_begin = k;
          prev = k;
          continue;
        }
        const int j = std::min(t0, t1);
        const int bit = std::countr_zero(static_cast<unsigned>((j + 1) << s));
        const int pair = bits - 1 - bit;
        const cv::Mat& P =
            cap_.images[static_cast<std::size_t>(cap_.pattern_indices[first + 2 * pair])];
        const cv::Mat& N =
            cap_.images[static_cast<std::size_t>(cap_.pattern_indices[first + 2 * pair + 1])];
        // The sign change of I - I_inv between prev and k (the first one; the midpoint if none).
        double pos = 0.5 * (prev + k);
        for (int m = prev; m < k; ++m) {
          const std::size_t im = start + static_cast<std::size_t>(m) * stride;
          const double d0 = diff(P, N, im), d1 = diff(P, N, im + stride);
          if ((d0 > 0) != (d1 > 0) && d0 != d1) {
            pos = m + std::clamp(d0 / (d0 - d1), 0.0, 1.0);
            break;
          }
        }
        edges.push_back({pos, (j + 1) * width - 0.5});
      }
      prev = k;
    }
    if (prev >= 0) flush(prev);
    edges.clear();
  }

  const SlCapture::Impl& cap_;
  const SlDecodeOptions& opt_;
  const SlDecoded& out_;
  const cv::Mat& white_;
  const cv::Mat& black_;
  int w_, h_;
};

template <class Pixel>
void refine_sub_stripe(const SlCapture::Impl& cap, const SlDecodeOptions& opt, SlDecoded& out) {
  const int w = cap.images[0].cols, h = cap.images[0].rows;
  const SubStripe<Pixel> sub(cap, opt, out);
  const SubStripeAxis axes[2] = {sub.run(0), sub.run(1)};
  const float nan = std::numeric_limits<float>::quiet_NaN();
  out.column_f = Image<float>(w, h, nan);
  out.row_f = Image<float>(w, h, nan);
  const cv::Mat& white = cap.images[static_cast<std::size_t>(cap.info.white_index)];
  const Pixel* W = reinterpret_cast<const Pixel*>(white.data);
  std::vector<std::size_t> bracketed_rows(static_cast<std::size_t>(h), 0);
  tbb::parallel_for(tbb::blocked_range<int>(0, h, 16), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y < rows.end(); ++y)
      for (int x = 0; x < w; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * w + x;
        if (out.status.data[i] != static_cast<std::uint8_t>(SlPixelStatus::kValid)) continue;
        double factor = 1.0;
        bool both = true;
        for (int a = 0; a < 2; ++a) {
          const auto& A = axes[a];
          const int bits = a == 0 ? cap.info.graycode.column_bits : cap.info.graycode.row_bits;
          const double stripe = static_cast<double>(1 << std::min(opt.sub_stripe_level, bits - 1));
          const float e0 = A.est[0][i], e1 = A.est[1][i];
          double v = a == 0 ? out.column.data[i] : out.row.data[i];
          if (!std::isnan(e0) && !std::isnan(e1)) {
            const double w0 = 1.0 / A.span[0][i], w1 = 1.0 / A.span[1][i];
            v = (w0 * e0 + w1 * e1) / (w0 + w1);
            const double dis = (e0 - e1) / (0.5 * stripe);
            factor *= std::exp(-dis * dis);
          } else if (!std::isnan(e0)) {
            v = e0;
          } else if (!std::isnan(e1)) {
            v = e1;
          } else {
            factor *= 0.5;
            both = false;
          }
          (a == 0 ? out.column_f : out.row_f).data[i] = static_cast<float>(v);
        }
        bracketed_rows[static_cast<std::size_t>(y)] += both;
        // Mixed pixels at printed texture edges: relative gradient of the white image.
        if (x > 0 && y > 0 && x + 1 < w && y + 1 < h) {
          const double gx = 0.5 * (static_cast<double>(W[i + 1]) - W[i - 1]);
          const double gy = 0.5 * (static_cast<double>(W[i + w]) - W[i - w]);
          const double g = std::hypot(gx, gy) / std::max(1.0, static_cast<double>(W[i]));
          factor /= 1.0 + (g / 0.25) * (g / 0.25);
        }
        out.confidence.data[i] = static_cast<float>(out.confidence.data[i] * factor);
      }
  });
  std::size_t bracketed = 0;
  for (std::size_t b : bracketed_rows) bracketed += b;
  out.sub_stripe_pixels = bracketed;
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
  if (o.sub_stripe_level < 0 || o.sub_stripe_level > 8)
    throw OptionError("sub-stripe level: " + std::to_string(o.sub_stripe_level) +
                      " out of range 0..8 (Gray-code bit)");
  if (!(o.sub_stripe_max_span_px > 1) || !(o.sub_stripe_max_span_px <= 1000))
    throw OptionError("sub-stripe max span: " + std::to_string(o.sub_stripe_max_span_px) +
                      " px, expected (1, 1000]");
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
  if (options.sub_stripe) {
    const int threads =
        options.threads > 0 ? options.threads : tbb::this_task_arena::max_concurrency();
    tbb::task_arena arena(threads);
    arena.execute([&] {
      if (capture.bit_depth() == 8)
        refine_sub_stripe<std::uint8_t>(cap, options, out);
      else
        refine_sub_stripe<std::uint16_t>(cap, options, out);
    });
  }
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  count(out);
  return out;
}

}  // namespace scanclean

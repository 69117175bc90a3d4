#include "scanclean/drivers/structured_light_source.h"

#include <array>
#include <chrono>
#include <cstdint>
#include <map>

#include "scanclean/core/errors.h"
#include "sl_capture_impl.h"

namespace scanclean {
namespace fs = std::filesystem;
namespace {

SlDecodeOptions decode_options(const SlOptions& o, const SlCaptureInfo& info) {
  SlDecodeOptions d;
  d.white_threshold = o.white_threshold >= 0 ? o.white_threshold : info.white_threshold;
  d.black_threshold = o.black_threshold >= 0 ? o.black_threshold : info.black_threshold;
  d.decoder = o.decoder;
  d.threads = o.threads;
  d.sub_stripe = o.sub_stripe;
  d.sub_stripe_level = o.sub_stripe_level;
  return d;
}

//! Reads the calibration for a capture and reconciles it with the capture's projector size.
SlCalibration calibration_for(const SlCaptureInfo& info, const SlOptions& o) {
  const fs::path file = !o.calibration.empty() ? o.calibration : info.calibration;
  if (file.empty())
    throw InputError(
        info.folder.string(), "",
        "no calibration: expected calib.yml (or the kamino410 "
        "calibration_result.xml) in the capture folder or its parent, or --calib FILE");
  SlCalibration c = read_sl_calibration(file);
  if (o.graycode_step > 0) c.graycode_step = o.graycode_step;
  const int pw = info.graycode.projector_width, ph = info.graycode.projector_height;
  const int step = c.graycode_step;
  if (c.projector.width == 0) {
    c.projector.width = pw * step;
    c.projector.height = ph * step;
  } else if ((c.projector.width - 1) / step + 1 != pw ||
             (c.projector.height - 1) / step + 1 != ph) {
    throw InputError(file.string(), "field 'proj_size'",
                     "calibrated projector is " + std::to_string(c.projector.width) + "x" +
                         std::to_string(c.projector.height) + " (Gray-code step " +
                         std::to_string(step) + "), the capture " + info.folder.string() +
                         " is for " + std::to_string(pw) + "x" + std::to_string(ph));
  }
  return c;
}

class TriangulatorCache {
 public:
  const SlTriangulator& get(const SlCalibration& c) {
    const std::string key = c.file.string() + "|" + std::to_string(c.projector.width) + "x" +
                            std::to_string(c.projector.height) + "|" +
                            std::to_string(c.graycode_step);
    auto it = cache_.find(key);
    if (it == cache_.end()) it = cache_.emplace(key, SlTriangulator(c)).first;
    return it->second;
  }

 private:
  std::map<std::string, SlTriangulator> cache_;
};

SlResult process(const fs::path& folder, const SlOptions& o, TriangulatorCache& cache) {
  validate(o);
  SlResult r;
  const auto t0 = std::chrono::steady_clock::now();
  r.info = describe_sl_capture(folder, o.projector_width, o.projector_height);
  r.calibration = calibration_for(r.info, o);
  const SlCapture capture = SlCapture::load(r.info);
  if (capture.width() != r.calibration.camera.width ||
      capture.height() != r.calibration.camera.height)
    throw InputError(r.info.images[0].string(), "",
                     "image size " + std::to_string(capture.width()) + "x" +
                         std::to_string(capture.height()) + ", but the calibration " +
                         r.calibration.file.string() + " is for " +
                         std::to_string(r.calibration.camera.width) + "x" +
                         std::to_string(r.calibration.camera.height) + " camera images");
  r.load_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.decoded = decode_graycode(capture, decode_options(o, r.info));
  r.capture = capture;
  if (o.graycode_step == 0 && r.calibration.layout == "kamino410") {
    const int step =
        estimate_graycode_step(r.decoded, r.calibration, &r.step_median_reprojection_px);
    r.graycode_step_estimated = true;
    r.calibration.graycode_step = step;
    r.calibration.projector.width = r.info.graycode.projector_width * step;
    r.calibration.projector.height = r.info.graycode.projector_height * step;
  }
  r.frame = cache.get(r.calibration).triangulate(r.decoded, o.triangulation, &r.triangulation);
  // The white image (the scene under full projector light) is the points' colour, in grey.
  const cv::Mat& white = capture.impl().images.at(static_cast<std::size_t>(r.info.white_index));
  if (white.cols == r.frame.width() && white.rows == r.frame.height()) {
    Image<std::array<std::uint8_t, 3>> grey(white.cols, white.rows);
    const int shift = white.depth() == CV_16U ? 8 : 0;
    for (int v = 0; v < white.rows; ++v)
      for (int u = 0; u < white.cols; ++u) {
        const auto g = static_cast<std::uint8_t>(shift ? white.at<std::uint16_t>(v, u) >> shift
                                                       : white.at<std::uint8_t>(v, u));
        grey(u, v) = {g, g, g};
      }
    r.frame.color = std::move(grey);
  }
  return r;
}

class StructuredLightSource final : public RangeSource {
 public:
  StructuredLightSource(fs::path path, SlOptions o)
      : path_(std::move(path)), options_(std::move(o)) {
    validate(options_);
  }

  void open() override {
    captures_ = find_structured_light_captures(path_);
    if (captures_.empty())
      throw InputError(path_.string(), "",
                       "no structured-light capture here or in its sub-folders (expected "
                       "capture.json or the kamino410 graycode_00.png)");
    // Check every layout and calibration up front, so a bad session fails at open().
    for (const auto& c : captures_) {
      const SlCaptureInfo info =
          describe_sl_capture(c, options_.projector_width, options_.projector_height);
      const SlCalibration calib = calibration_for(info, options_);
      if (c == captures_.front()) {
        info_.K = calib.camera;
        info_.serial = info.camera_serial;
      }
    }
    info_.uri = path_.string();
    info_.kind = "structured-light";
    info_.vendor = "";
    info_.name = "Gray-code projector-camera capture";
    info_.is_live = false;
    info_.frame_count = captures_.size();
    info_.depth_unit_m = options_.triangulation.depth_unit_m;
    info_.noise_model = "structured-light";
    next_ = 0;
    opened_ = true;
  }

  ReadStatus next(RangeFrame& frame, std::chrono::milliseconds) override {
    if (!opened_) {
      error_ = "structured-light source: next() before open()";
      return ReadStatus::kError;
    }
    if (next_ >= captures_.size()) return ReadStatus::kEndOfStream;
    const std::size_t i = next_++;
    try {
      SlResult r = process(captures_[i], options_, cache_);
      frame = std::move(r.frame);
      frame.index = i;
      frame.device_ts_us = 0;
      frame.host_ts_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                             std::chrono::steady_clock::now().time_since_epoch())
                             .count();
      return ReadStatus::kOk;
    } catch (const Error& e) {
      error_ = e.what();
      return ReadStatus::kError;
    }
  }

  SourceInfo info() const override { return info_; }
  void close() override {
    opened_ = false;
    cache_ = TriangulatorCache();
  }
  std::string last_error() const override { return error_; }

 private:
  fs::path path_;
  SlOptions options_;
  std::vector<fs::path> captures_;
  std::size_t next_ = 0;
  bool opened_ = false;
  SourceInfo info_;
  std::string error_;
  TriangulatorCache cache_;
};

}  // namespace

void validate(const SlOptions& o) {
  if (o.white_threshold > 65535)
    throw OptionError("white threshold: " + std::to_string(o.white_threshold) +
                      " out of range 0..65535 (gray levels; < 0 = the capture's)");
  if (o.black_threshold > 65535)
    throw OptionError("black threshold: " + std::to_string(o.black_threshold) +
                      " out of range 0..65535 (gray levels; < 0 = the capture's)");
  if ((o.projector_width > 0) != (o.projector_height > 0) || o.projector_width < 0 ||
      o.projector_height < 0)
    throw OptionError("projector size: give both width and height (> 0) or neither");
  if (o.threads < 0) throw OptionError("threads: expected >= 0");
  if (o.graycode_step < 0 || o.graycode_step > 64)
    throw OptionError("graycode step: " + std::to_string(o.graycode_step) +
                      " out of range 1..64 (0 = the calibration's)");
  validate(o.triangulation);
}

std::unique_ptr<RangeSource> make_structured_light_source(const fs::path& capture,
                                                          const SlOptions& options) {
  return std::make_unique<StructuredLightSource>(capture, options);
}

SlResult process_sl_capture(const fs::path& folder, const SlOptions& options) {
  TriangulatorCache cache;
  return process(folder, options, cache);
}

PointCloud sl_frame_to_cloud(const RangeFrame& frame) {
  PointCloud cloud;
  if (!frame.points) return cloud;
  const auto& P = *frame.points;
  cloud.grid.rows = P.height;
  cloud.grid.cols = P.width;
  cloud.grid.index.assign(P.size(), -1);
  for (std::size_t i = 0; i < P.size(); ++i) {
    if (!P.data[i].allFinite()) continue;
    cloud.grid.index[i] = static_cast<std::int32_t>(cloud.positions.size());
    cloud.positions.push_back(P.data[i].cast<double>());
    cloud.confidences.push_back(frame.confidence ? frame.confidence->data[i] : 1.0f);
    if (frame.color) {
      const auto& c = frame.color->data[i];
      cloud.colors.push_back({c[0], c[1], c[2], 255});
    }
  }
  return cloud;
}

}  // namespace scanclean

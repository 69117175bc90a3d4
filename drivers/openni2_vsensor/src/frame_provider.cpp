#include "frame_provider.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <stdexcept>
#include <string_view>

#include "scanclean/replay/recording_reader.h"

namespace scanclean::vsensor {
namespace {

constexpr std::string_view kScheme = "vsensor://";
// The field of view the pattern reports (a typical PrimeSense VGA depth camera).
constexpr double kPatternHfov = 1.0226, kPatternVfov = 0.7966;

std::size_t parse_count(std::string_view key, std::string_view text) {
  std::size_t value = 0;
  const auto* end = text.data() + text.size();
  const auto [ptr, ec] = std::from_chars(text.data(), end, value);
  if (ec != std::errc() || ptr != end || text.empty())
    throw std::invalid_argument("vsensor URI: parameter '" + std::string(key) +
                                "' expects a non-negative integer, got '" + std::string(text) +
                                "'");
  return value;
}

class PatternProvider final : public FrameProvider {
 public:
  explicit PatternProvider(const VsensorUri& uri) : uri_(uri) {}
  int width() const override { return uri_.pattern_width; }
  int height() const override { return uri_.pattern_height; }
  double unit_m() const override { return uri_.pattern_100um ? 0.0001 : 0.001; }
  double hfov_rad() const override { return kPatternHfov; }
  double vfov_rad() const override { return kPatternVfov; }
  int fps() const override { return uri_.pattern_fps; }
  std::size_t frame_count() const override { return uri_.pattern_frames; }
  ProvidedFrame stamp(std::size_t i) const override {
    ProvidedFrame f;
    f.index = i + 1;
    f.device_ts_us = static_cast<std::int64_t>(i) * 1000000 / uri_.pattern_fps;
    return f;
  }
  ProvidedFrame frame(std::size_t i) const override {
    ProvidedFrame f = stamp(i);
    f.depth.resize(static_cast<std::size_t>(width()) * height());
    for (int v = 0; v < height(); ++v)
      for (int u = 0; u < width(); ++u)
        f.depth[static_cast<std::size_t>(v) * width() + u] = pattern_value(u, v, i);
    return f;
  }

 private:
  VsensorUri uri_;
};

class RecordingProvider final : public FrameProvider {
 public:
  explicit RecordingProvider(const std::string& folder) : reader_(folder) {
    const SessionMetadata& s = reader_.session();
    if (s.K.valid()) {
      hfov_ = 2.0 * std::atan(s.width / (2.0 * s.K.fx));
      vfov_ = 2.0 * std::atan(s.height / (2.0 * s.K.fy));
    }
    // Frame rate from the median timestamp step (30 when unknown).
    std::vector<std::int64_t> steps;
    for (std::size_t i = 1; i < reader_.frame_count(); ++i)
      steps.push_back(reader_.record(i).device_ts_us - reader_.record(i - 1).device_ts_us);
    if (!steps.empty()) {
      std::nth_element(steps.begin(), steps.begin() + steps.size() / 2, steps.end());
      const std::int64_t step = steps[steps.size() / 2];
      if (step > 0) fps_ = std::clamp(static_cast<int>(std::lround(1e6 / step)), 1, 1000);
    }
  }
  int width() const override { return reader_.session().width; }
  int height() const override { return reader_.session().height; }
  double unit_m() const override { return reader_.session().unit_m; }
  double hfov_rad() const override { return hfov_; }
  double vfov_rad() const override { return vfov_; }
  int fps() const override { return fps_; }
  std::size_t frame_count() const override { return reader_.frame_count(); }
  ProvidedFrame frame(std::size_t i) const override {
    RangeFrame rf = reader_.read_frame(i);
    ProvidedFrame f;
    f.index = rf.index;
    f.device_ts_us = rf.device_ts_us;
    f.depth = std::move(rf.depth.data);
    return f;
  }
  ProvidedFrame stamp(std::size_t i) const override {
    ProvidedFrame f;
    f.index = reader_.record(i).index;
    f.device_ts_us = reader_.record(i).device_ts_us;
    return f;
  }
  std::optional<Ps1080Params> ps1080() const override { return reader_.session().ps1080; }
  std::string serial() const override { return reader_.session().device.serial; }
  std::string device_name() const override {
    const auto& d = reader_.session().device;
    return d.name.empty() ? "Virtual Sensor" : "Virtual Sensor (" + d.name + ")";
  }

 private:
  RecordingReader reader_;
  double hfov_ = kPatternHfov, vfov_ = kPatternVfov;
  int fps_ = 30;
};

}  // namespace

std::uint16_t pattern_value(int u, int v, std::size_t position) {
  const std::size_t p = position;
  if ((static_cast<std::size_t>(u) + 3 * static_cast<std::size_t>(v) + p) % 23 == 0) return 0;
  return static_cast<std::uint16_t>(
      500 + (static_cast<std::size_t>(u) * 7 + static_cast<std::size_t>(v) * 13 + p * 31) % 4000);
}

VsensorUri parse_vsensor_uri(const std::string& uri) {
  if (uri.rfind(kScheme, 0) != 0)
    throw std::invalid_argument("not a vsensor URI (expected vsensor://...): '" + uri + "'");
  VsensorUri out;
  out.uri = uri;
  std::string_view rest = std::string_view(uri).substr(kScheme.size());
  const std::size_t q = rest.find('?');
  const std::string_view target = rest.substr(0, q);
  const std::string_view query = q == std::string_view::npos ? "" : rest.substr(q + 1);
  if (target == "default" || target == "pattern") {
    out.pattern = true;
  } else {
    if (target.empty() || target.front() != '/')
      throw std::invalid_argument(
          "vsensor URI: expected an absolute recording folder, 'pattern' or 'default' after "
          "vsensor://, got '" +
          std::string(target) + "'");
    out.folder = std::string(target);
  }
  std::size_t pos = 0;
  while (pos < query.size()) {
    std::size_t amp = query.find('&', pos);
    if (amp == std::string_view::npos) amp = query.size();
    const std::string_view item = query.substr(pos, amp - pos);
    pos = amp + 1;
    if (item.empty()) continue;
    const std::size_t eq = item.find('=');
    if (eq == std::string_view::npos)
      throw std::invalid_argument("vsensor URI: parameter '" + std::string(item) +
                                  "' has no value (expected key=value)");
    const std::string_view key = item.substr(0, eq), value = item.substr(eq + 1);
    if (key == "pace") {
      if (value == "manual")
        out.realtime = false;
      else if (value == "realtime")
        out.realtime = true;
      else
        throw std::invalid_argument("vsensor URI: pace must be manual or realtime, got '" +
                                    std::string(value) + "'");
    } else if (key == "loop") {
      out.loop = parse_count(key, value) != 0;
    } else if (key == "drop") {
      if (value.rfind("every", 0) == 0) {
        std::string_view n = value.substr(5);
        if (!n.empty() && n.front() == ':') n.remove_prefix(1);
        out.drop_every = parse_count(key, n);
        if (out.drop_every < 2)
          throw std::invalid_argument("vsensor URI: drop=every<N> needs N >= 2");
      } else {
        std::size_t p = 0;
        while (p <= value.size()) {
          std::size_t comma = value.find(',', p);
          if (comma == std::string_view::npos) comma = value.size();
          out.drop_positions.insert(parse_count(key, value.substr(p, comma - p)));
          p = comma + 1;
        }
      }
    } else if (key == "disconnect_after") {
      out.disconnect_after = parse_count(key, value);
    } else if (key == "w" && out.pattern) {
      out.pattern_width =
          static_cast<int>(std::clamp<std::size_t>(parse_count(key, value), 1, 4096));
    } else if (key == "h" && out.pattern) {
      out.pattern_height =
          static_cast<int>(std::clamp<std::size_t>(parse_count(key, value), 1, 4096));
    } else if (key == "n" && out.pattern) {
      out.pattern_frames = parse_count(key, value);
    } else if (key == "fps" && out.pattern) {
      out.pattern_fps = static_cast<int>(std::clamp<std::size_t>(parse_count(key, value), 1, 1000));
    } else if (key == "unit" && out.pattern) {
      if (value == "mm")
        out.pattern_100um = false;
      else if (value == "100um")
        out.pattern_100um = true;
      else
        throw std::invalid_argument("vsensor URI: unit must be mm or 100um, got '" +
                                    std::string(value) + "'");
    } else {
      throw std::invalid_argument(
          "vsensor URI: unknown parameter '" + std::string(key) +
          "' (known: pace, loop, drop, disconnect_after; pattern: w, h, n, fps, unit)");
    }
  }
  return out;
}

std::unique_ptr<FrameProvider> make_frame_provider(const VsensorUri& uri) {
  if (uri.pattern) return std::make_unique<PatternProvider>(uri);
  return std::make_unique<RecordingProvider>(uri.folder);
}

}  // namespace scanclean::vsensor

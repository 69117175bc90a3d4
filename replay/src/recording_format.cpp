#include "scanclean/replay/recording_format.h"

#include <ctime>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <system_error>

#include "json_input.h"
#include "scanclean/core/atomic_file.h"
#include "scanclean/core/errors.h"

namespace scanclean {

namespace {

using nlohmann::json;

std::string type_name(const json& j) {
  if (j.is_null()) return "null";
  if (j.is_boolean()) return "a boolean";
  if (j.is_number_integer()) return "an integer";
  if (j.is_number()) return "a number";
  if (j.is_string()) return "a string";
  if (j.is_array()) return "an array";
  return "an object";
}

std::string shown(const json& j) {
  std::string s = j.dump();
  if (s.size() > 40) s = s.substr(0, 37) + "...";
  return type_name(j) + " " + s;
}

//! Field access with InputErrors that name the file and the dotted field path.
class Fields {
 public:
  Fields(const json& object, std::string file, std::string prefix)
      : j_(object), file_(std::move(file)), prefix_(std::move(prefix)) {}

  [[noreturn]] void fail(const std::string& key, const std::string& what) const {
    throw InputError(file_, "field " + prefix_ + key, what);
  }
  bool has(const std::string& key) const { return j_.contains(key) && !j_.at(key).is_null(); }
  const json& at(const std::string& key) const {
    if (!j_.contains(key)) fail(key, "missing (required by " + std::string(kRecordingFormat) + ")");
    return j_.at(key);
  }
  std::string str(const std::string& key) const {
    const json& v = at(key);
    if (!v.is_string()) fail(key, "expected a string, got " + shown(v));
    return v.get<std::string>();
  }
  std::string str_or(const std::string& key, const std::string& fallback) const {
    return j_.contains(key) ? str(key) : fallback;
  }
  double num(const std::string& key) const {
    const json& v = at(key);
    if (!v.is_number()) fail(key, "expected a number, got " + shown(v));
    return v.get<double>();
  }
  double positive(const std::string& key) const {
    double v = num(key);
    if (!(v > 0)) fail(key, "expected a positive number, got " + at(key).dump());
    return v;
  }
  int positive_int(const std::string& key, int max_value) const {
    const json& v = at(key);
    if (!v.is_number_integer() || v.get<std::int64_t>() <= 0 || v.get<std::int64_t>() > max_value)
      fail(key, "expected an integer in 1.." + std::to_string(max_value) + ", got " + shown(v));
    return static_cast<int>(v.get<std::int64_t>());
  }
  bool boolean(const std::string& key) const {
    const json& v = at(key);
    if (!v.is_boolean()) fail(key, "expected true or false, got " + shown(v));
    return v.get<bool>();
  }
  Fields object(const std::string& key) const {
    const json& v = at(key);
    if (!v.is_object()) fail(key, "expected an object, got " + shown(v));
    return Fields(v, file_, prefix_ + key + ".");
  }
  template <std::size_t N>
  std::array<double, N> numbers(const std::string& key) const {
    const json& v = at(key);
    if (!v.is_array() || v.size() != N)
      fail(key, "expected an array of " + std::to_string(N) + " numbers, got " + shown(v));
    std::array<double, N> out{};
    for (std::size_t i = 0; i < N; ++i) {
      if (!v[i].is_number())
        fail(key, "element " + std::to_string(i) + ": expected a number, got " + shown(v[i]));
      out[i] = v[i].get<double>();
    }
    return out;
  }

 private:
  const json& j_;
  std::string file_;
  std::string prefix_;
};

constexpr int kMaxSide = 1 << 15;  // 32768 pixels: far beyond any depth sensor

}  // namespace

SessionMetadata session_from_info(const SourceInfo& info, int width, int height) {
  if (width <= 0 || height <= 0)
    throw OptionError("session_from_info: depth size must be positive, got " +
                      std::to_string(width) + "x" + std::to_string(height));
  SessionMetadata s;
  s.device.kind = info.kind;
  s.device.vendor = info.vendor;
  s.device.name = info.name;
  s.device.uri = info.uri;
  s.device.usb = info.usb_id;
  s.device.serial = info.serial;
  s.device.firmware = info.firmware;
  s.width = width;
  s.height = height;
  s.unit_m = info.depth_unit_m;
  s.K = info.K;
  if (!(info.K.fx > 0 && info.K.fy > 0)) {  // no usable intrinsics: store zeros, keep the origin
    s.K = Intrinsics{};
    s.K.source = info.K.source;
  }
  s.K.width = width;
  s.K.height = height;
  s.noise_model = info.noise_model;
  s.ps1080 = info.ps1080;
  return s;
}

SourceInfo info_from_session(const SessionMetadata& session, const std::string& uri) {
  SourceInfo info;
  info.uri = uri;
  info.kind = "recording";
  info.vendor = session.device.vendor;
  info.name = session.device.name;
  info.serial = session.device.serial;
  info.usb_id = session.device.usb;
  info.firmware = session.device.firmware;
  info.is_live = false;
  if (session.finalized && session.frame_count) info.frame_count = session.frame_count;
  info.K = session.K;
  info.K.width = session.width;
  info.K.height = session.height;
  info.depth_unit_m = session.unit_m;
  info.noise_model = session.noise_model;
  info.ps1080 = session.ps1080;
  return info;
}

std::string session_to_json(const SessionMetadata& s) {
  json j;
  j["format"] = s.format;
  j["device"] = {{"kind", s.device.kind},        {"vendor", s.device.vendor},
                 {"name", s.device.name},        {"uri", s.device.uri},
                 {"usb", s.device.usb},          {"serial", s.device.serial},
                 {"firmware", s.device.firmware}};
  j["depth"] = {{"width", s.width}, {"height", s.height}, {"unit_m", s.unit_m}, {"invalid", 0}};
  j["intrinsics"] = {{"fx", s.K.fx}, {"fy", s.K.fy},     {"cx", s.K.cx},
                     {"cy", s.K.cy}, {"dist", s.K.dist}, {"source", s.K.source}};
  j["noise_model"] = {{"name", s.noise_model}};
  if (s.ps1080)
    j["ps1080"] = {{"zpd_mm", s.ps1080->zpd_mm},
                   {"zpps_mm", s.ps1080->zpps_mm},
                   {"lddis_cm", s.ps1080->lddis_cm},
                   {"param_coeff", s.ps1080->param_coeff}};
  j["registration"] = s.registration;
  if (s.extrinsics_depth_to_color)
    j["extrinsics_depth_to_color"] = {{"R", s.extrinsics_depth_to_color->R},
                                      {"T", s.extrinsics_depth_to_color->T}};
  j["created"] = s.created;
  j["finalized"] = s.finalized;
  if (s.frame_count) j["frame_count"] = *s.frame_count;
  return j.dump(2) + "\n";
}

SessionMetadata session_from_json(const std::string& text, const std::string& file) {
  const json j = detail::parse_json_input(text, file);
  if (!j.is_object()) throw InputError(file, "", "expected a JSON object, got " + shown(j));
  Fields root(j, file, "");
  SessionMetadata s;
  s.format = root.str("format");
  if (s.format != kRecordingFormat)
    root.fail("format", "unsupported recording format \"" + s.format + "\" (this build reads \"" +
                            kRecordingFormat + "\")");

  Fields dev = root.object("device");
  s.device.kind = dev.str_or("kind", "");
  s.device.vendor = dev.str_or("vendor", "");
  s.device.name = dev.str_or("name", "");
  s.device.uri = dev.str_or("uri", "");
  s.device.usb = dev.str_or("usb", "");
  s.device.serial = dev.str_or("serial", "");
  s.device.firmware = dev.str_or("firmware", "");

  Fields depth = root.object("depth");
  s.width = depth.positive_int("width", kMaxSide);
  s.height = depth.positive_int("height", kMaxSide);
  s.unit_m = depth.positive("unit_m");
  if (depth.has("invalid")) {
    const json& inv = depth.at("invalid");
    if (!inv.is_number_integer() || inv.get<std::int64_t>() != 0)
      depth.fail("invalid",
                 "expected 0 (the only invalid-depth value of format v1), got " + shown(inv));
  }

  Fields in = root.object("intrinsics");
  s.K.fx = in.num("fx");
  s.K.fy = in.num("fy");
  s.K.cx = in.num("cx");
  s.K.cy = in.num("cy");
  if (s.K.fx < 0 || s.K.fy < 0) in.fail("fx", "focal lengths must not be negative");
  s.K.dist = in.has("dist") ? in.numbers<5>("dist") : std::array<double, 5>{};
  s.K.source = in.str_or("source", "fov");
  if (s.K.source != "fov" && s.K.source != "calibration")
    in.fail("source", "expected \"fov\" or \"calibration\", got \"" + s.K.source + "\"");
  s.K.width = s.width;
  s.K.height = s.height;

  if (root.has("noise_model")) {
    Fields nm = root.object("noise_model");
    s.noise_model = nm.str("name");
    if (s.noise_model != "nguyen2012" && s.noise_model != "structured-light" &&
        s.noise_model != "none")
      nm.fail("name", "expected \"nguyen2012\", \"structured-light\" or \"none\", got \"" +
                          s.noise_model + "\"");
  }
  if (root.has("ps1080")) {
    Fields ps = root.object("ps1080");
    Ps1080Params p;
    p.zpd_mm = ps.num("zpd_mm");
    p.zpps_mm = ps.num("zpps_mm");
    p.lddis_cm = ps.num("lddis_cm");
    p.param_coeff = ps.num("param_coeff");
    s.ps1080 = p;
  }
  s.registration = root.str_or("registration", "off");
  if (s.registration != "off" && s.registration != "depth_to_color")
    root.fail("registration",
              "expected \"off\" or \"depth_to_color\", got \"" + s.registration + "\"");
  if (root.has("extrinsics_depth_to_color")) {
    Fields ex = root.object("extrinsics_depth_to_color");
    DepthToColor e;
    e.R = ex.numbers<9>("R");
    e.T = ex.numbers<3>("T");
    s.extrinsics_depth_to_color = e;
  }
  s.created = root.str_or("created", "");
  s.finalized = root.has("finalized") ? root.boolean("finalized") : false;
  if (root.has("frame_count")) {
    const json& v = root.at("frame_count");
    if (!v.is_number_unsigned() && !(v.is_number_integer() && v.get<std::int64_t>() >= 0))
      root.fail("frame_count", "expected a non-negative integer, got " + shown(v));
    s.frame_count = v.get<std::uint64_t>();
  }
  if (s.finalized && !s.frame_count)
    root.fail("frame_count", "missing in a finalized recording (\"finalized\": true)");
  return s;
}

SessionMetadata read_session(const std::filesystem::path& folder) {
  const std::filesystem::path file = folder / kSessionFileName;
  std::error_code ec;
  if (!std::filesystem::is_regular_file(file, ec)) {
    if (!std::filesystem::is_directory(folder, ec))
      throw InputError(folder.string(), "", "not a folder (expected a recording folder)");
    throw InputError(file.string(), "",
                     "missing: not a recording folder (format " + std::string(kRecordingFormat) +
                         " starts with session.json)");
  }
  const auto size = std::filesystem::file_size(file, ec);
  if (ec) throw IoError(file.string() + ": cannot stat: " + ec.message());
  if (size > (1u << 20))
    throw InputError(file.string(), "",
                     "larger than 1 MiB (" + std::to_string(size) + " bytes): not a session file");
  std::ifstream in(file, std::ios::binary);
  if (!in) throw IoError(file.string() + ": cannot open for reading");
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) throw IoError(file.string() + ": read failed");
  return session_from_json(text.str(), file.string());
}

void write_session(const std::filesystem::path& folder, const SessionMetadata& session) {
  const std::string text = session_to_json(session);
  write_file_atomically(folder / kSessionFileName, [&](std::ostream& out) { out << text; });
}

bool is_recording_folder(const std::filesystem::path& path) {
  std::error_code ec;
  return std::filesystem::is_directory(path, ec) &&
         std::filesystem::is_regular_file(path / kSessionFileName, ec);
}

std::string utc_now_iso8601() {
  std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

}  // namespace scanclean

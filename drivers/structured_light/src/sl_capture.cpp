#include "scanclean/drivers/sl_capture.h"

#include <algorithm>
#include <array>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/structured_light.hpp>
#include <set>

#include "scanclean/core/atomic_file.h"
#include "scanclean/core/errors.h"
#include "sl_capture_impl.h"

namespace scanclean {
namespace fs = std::filesystem;
namespace {

//! A capture description is a few hundred bytes; anything beyond this is not one.
constexpr std::size_t kMaxCaptureDescriptionBytes = 65536;

int ceil_log2(int v) {
  int bits = 0;
  while ((1 << bits) < v) ++bits;
  return bits;
}

std::string index_name(int index, int digits) {
  std::string s = std::to_string(index);
  if (static_cast<int>(s.size()) < digits)
    s.insert(0, static_cast<std::size_t>(digits) - s.size(), '0');
  return s + ".png";
}

bool exists_file(const fs::path& p) {
  std::error_code ec;
  return fs::is_regular_file(p, ec);
}

//! Width and height from a PNG header without decoding, or nullopt when not a PNG.
std::optional<std::array<int, 2>> png_size(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  unsigned char h[24];
  if (!in.read(reinterpret_cast<char*>(h), sizeof h)) return std::nullopt;
  static const unsigned char sig[8] = {0x89, 'P', 'N', 'G', 0x0D, 0x0A, 0x1A, 0x0A};
  if (!std::equal(sig, sig + 8, h) || std::string(reinterpret_cast<char*>(h + 12), 4) != "IHDR")
    return std::nullopt;
  auto be = [&](int o) {
    return static_cast<long long>(h[o]) << 24 | static_cast<long long>(h[o + 1]) << 16 |
           static_cast<long long>(h[o + 2]) << 8 | static_cast<long long>(h[o + 3]);
  };
  const long long w = be(16), ht = be(20);
  if (w <= 0 || ht <= 0 || w > 1 << 20 || ht > 1 << 20) return std::array<int, 2>{-1, -1};
  return std::array<int, 2>{static_cast<int>(w), static_cast<int>(ht)};
}

fs::path find_calibration(const fs::path& folder) {
  for (const fs::path& dir : {folder, folder.parent_path()}) {
    if (dir.empty()) continue;
    for (const char* name : {"calib.yml", "calib.yaml", "calib.xml", "calibration_result.xml"})
      if (exists_file(dir / name)) return dir / name;
  }
  return {};
}

template <class T>
T json_get(const nlohmann::json& j, const char* key, const fs::path& file, const std::string& where,
           const char* expected) {
  if (!j.contains(key))
    throw InputError(file.string(), where + key, std::string("missing (") + expected + ")");
  try {
    return j.at(key).get<T>();
  } catch (const nlohmann::json::exception&) {
    throw InputError(file.string(), where + key, std::string("expected ") + expected);
  }
}

//! An integer item: a JSON integer within int's range (a fraction or 1e10 is refused rather than
//! cast, which would be undefined behaviour for values out of range).
int json_int(const nlohmann::json& j, const char* key, const fs::path& file,
             const std::string& where) {
  if (!j.contains(key)) throw InputError(file.string(), where + key, "missing (an integer)");
  const auto& v = j.at(key);
  if (!v.is_number_integer())
    throw InputError(file.string(), where + key, "expected an integer, got " + v.dump());
  if (v.is_number_unsigned()
          ? v.get<std::uint64_t>() > 2147483647u
          : (v.get<std::int64_t>() < -2147483647 - 1 || v.get<std::int64_t>() > 2147483647))
    throw InputError(file.string(), where + key, "integer " + v.dump() + " out of range");
  return static_cast<int>(v.get<std::int64_t>());
}

SlCaptureInfo describe_scanclean(const fs::path& folder, int pw, int ph) {
  const fs::path file = folder / "capture.json";
  // A capture description is a few hundred bytes; refuse anything large before reading it.
  std::error_code ec;
  const auto size = fs::file_size(file, ec);
  if (!ec && size > kMaxCaptureDescriptionBytes)
    throw InputError(file.string(), "",
                     "larger than " + std::to_string(kMaxCaptureDescriptionBytes) + " bytes (" +
                         std::to_string(size) + "): not a capture description");
  std::ifstream in(file, std::ios::binary);
  if (!in) throw IoError(file.string() + ": cannot open");
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw IoError(file.string() + ": read error");
  SlCaptureInfo info = parse_sl_capture_description(text, file, pw, ph);
  info.calibration = find_calibration(folder);
  return info;
}

}  // namespace

SlCaptureInfo parse_sl_capture_description(std::string_view text, const fs::path& file, int pw,
                                           int ph) {
  const fs::path folder = file.parent_path();
  if (text.size() > kMaxCaptureDescriptionBytes)
    throw InputError(file.string(), "",
                     "larger than " + std::to_string(kMaxCaptureDescriptionBytes) +
                         " bytes: not a capture description");
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(text.begin(), text.end());
  } catch (const nlohmann::json::parse_error& e) {
    throw InputError(file.string(), byte_place(e.byte), "invalid JSON");
  } catch (const nlohmann::json::out_of_range&) {
    throw InputError(file.string(), "", "a number out of range (expected finite numbers)");
  } catch (const nlohmann::json::exception& e) {
    throw InputError(file.string(), "", std::string("invalid JSON: ") + e.what());
  }
  if (!j.is_object()) throw InputError(file.string(), "", "expected a JSON object");
  const auto format = json_get<std::string>(j, "format", file, "", "\"scanclean-sl/1\"");
  if (format != "scanclean-sl/1")
    throw InputError(file.string(), "format",
                     "expected \"scanclean-sl/1\", got \"" + format + "\"");
  const auto pattern = json_get<std::string>(j, "pattern", file, "", "\"graycode\"");
  if (pattern != "graycode")
    throw InputError(file.string(), "pattern",
                     "only \"graycode\" is supported, got \"" + pattern + "\"");
  const auto order = json_get<std::string>(j, "order", file, "", "\"opencv\"");
  if (order != "opencv")
    throw InputError(
        file.string(), "order",
        "only \"opencv\" (GrayCodePattern::generate order) is supported, got \"" + order + "\"");
  if (!j.contains("projector") || !j["projector"].is_object())
    throw InputError(file.string(), "projector", "missing (object {\"width\", \"height\"})");
  int width = json_int(j["projector"], "width", file, "projector.");
  int height = json_int(j["projector"], "height", file, "projector.");
  if (pw > 0 && ph > 0) {
    width = pw;
    height = ph;
  }
  if (width < 2 || height < 2 || width > 65535 || height > 65535)
    throw InputError(
        file.string(), "projector",
        "size " + std::to_string(width) + "x" + std::to_string(height) + " out of range 2..65535");
  SlCaptureInfo info;
  info.folder = folder;
  info.layout = "scanclean";
  info.graycode = graycode_layout(width, height);
  const int count = json_int(j, "count", file, "");
  if (count != info.graycode.pattern_count())
    throw InputError(file.string(), "count",
                     std::to_string(count) + " Gray-code images, but a " + std::to_string(width) +
                         "x" + std::to_string(height) + " projector needs " +
                         std::to_string(info.graycode.pattern_count()) + " (2 x (" +
                         std::to_string(info.graycode.column_bits) + " column + " +
                         std::to_string(info.graycode.row_bits) + " row bits))");
  const int total = count + 2;
  info.white_index = json_int(j, "white_index", file, "");
  info.black_index = json_int(j, "black_index", file, "");
  for (auto [name, v] :
       {std::pair{"white_index", info.white_index}, {"black_index", info.black_index}})
    if (v < 0 || v >= total)
      throw InputError(file.string(), name,
                       std::to_string(v) + " out of range 0.." + std::to_string(total - 1));
  if (info.white_index == info.black_index)
    throw InputError(file.string(), "black_index", "equals white_index");
  if (j.contains("thresholds")) {
    const auto& t = j["thresholds"];
    if (!t.is_object()) throw InputError(file.string(), "thresholds", "expected an object");
    if (t.contains("white")) info.white_threshold = json_int(t, "white", file, "thresholds.");
    if (t.contains("black")) info.black_threshold = json_int(t, "black", file, "thresholds.");
    if (info.white_threshold < 0 || info.black_threshold < 0)
      throw InputError(file.string(), "thresholds", "must be >= 0");
  }
  std::string image_dir = "img";
  if (j.contains("image_dir"))
    image_dir = json_get<std::string>(j, "image_dir", file, "", "a folder name");
  if (image_dir.empty() || fs::path(image_dir).is_absolute() ||
      image_dir.find("..") != std::string::npos)
    throw InputError(file.string(), "image_dir",
                     "expected a relative folder name inside the capture");
  if (j.contains("exposure_us")) {
    info.exposure_us = json_get<double>(j, "exposure_us", file, "", "a number");
    if (!(*info.exposure_us >= 0))
      throw InputError(file.string(), "exposure_us", "expected microseconds >= 0");
  }
  if (j.contains("camera_serial"))
    info.camera_serial = json_get<std::string>(j, "camera_serial", file, "", "a string");
  const int digits = std::max(3, static_cast<int>(std::to_string(total - 1).size()));
  for (int k = 0; k < total; ++k) info.images.push_back(folder / image_dir / index_name(k, digits));
  return info;
}

namespace {

SlCaptureInfo describe_kamino(const fs::path& folder, int pw, int ph) {
  SlCaptureInfo info;
  info.folder = folder;
  info.layout = "kamino410";
  int n = 0;
  for (;; ++n) {
    char name[40];
    std::snprintf(name, sizeof name, "graycode_%02d.png", n);
    if (!exists_file(folder / name)) break;
    info.images.push_back(folder / name);
  }
  // A gap (graycode_05 missing while graycode_06 exists) is a missing image, not the end.
  for (int k = n + 1; k < n + 4; ++k) {
    char name[40];
    std::snprintf(name, sizeof name, "graycode_%02d.png", k);
    if (exists_file(folder / name)) {
      std::snprintf(name, sizeof name, "graycode_%02d.png", n);
      throw InputError((folder / name).string(), "", "missing (later images exist)");
    }
  }
  if (pw <= 0 || ph <= 0) {
    const fs::path pattern = folder.parent_path() / "graycode_pattern" / "pattern_00.png";
    const auto size = exists_file(pattern) ? png_size(pattern) : std::nullopt;
    if (!size || (*size)[0] <= 0)
      throw InputError(folder.string(), "",
                       "kamino410 capture: projector size unknown (give it with --projector WxH, "
                       "or keep ../graycode_pattern/pattern_00.png beside the capture)");
    pw = (*size)[0];
    ph = (*size)[1];
  }
  info.graycode = graycode_layout(pw, ph);
  const int expected = info.graycode.pattern_count() + 2;
  if (n != expected)
    throw InputError(
        folder.string(), "",
        "kamino410 capture: " + std::to_string(n) + " images graycode_00.. found, but a " +
            std::to_string(pw) + "x" + std::to_string(ph) + " projector needs " +
            std::to_string(expected) + " (" + std::to_string(info.graycode.pattern_count()) +
            " Gray-code images + white + black)" +
            (n < expected ? "; first missing: " + index_name(n, 2).insert(0, "graycode_") : ""));
  info.white_index = n - 2;
  info.black_index = n - 1;
  info.calibration = find_calibration(folder);
  return info;
}

}  // namespace

GrayCodeLayout graycode_layout(int projector_width, int projector_height) {
  if (projector_width < 2 || projector_width > 65535 || projector_height < 2 ||
      projector_height > 65535)
    throw OptionError("projector size " + std::to_string(projector_width) + "x" +
                      std::to_string(projector_height) + " out of range 2..65535");
  GrayCodeLayout l;
  l.projector_width = projector_width;
  l.projector_height = projector_height;
  l.column_bits = ceil_log2(projector_width);
  l.row_bits = ceil_log2(projector_height);
  const auto pattern =
      cv::structured_light::GrayCodePattern::create(projector_width, projector_height);
  if (static_cast<int>(pattern->getNumberOfPatternImages()) != l.pattern_count())
    throw OptionError("projector size " + std::to_string(projector_width) + "x" +
                      std::to_string(projector_height) + ": OpenCV generates " +
                      std::to_string(pattern->getNumberOfPatternImages()) +
                      " Gray-code images, expected " + std::to_string(l.pattern_count()));
  return l;
}

bool is_structured_light_capture(const fs::path& path) {
  std::error_code ec;
  if (!fs::is_directory(path, ec)) return false;
  return exists_file(path / "capture.json") || exists_file(path / "graycode_00.png");
}

std::vector<fs::path> find_structured_light_captures(const fs::path& path) {
  if (is_structured_light_capture(path)) return {path};
  std::vector<fs::path> out;
  std::error_code ec;
  if (!fs::is_directory(path, ec)) return out;
  for (const auto& e : fs::directory_iterator(path, ec))
    if (is_structured_light_capture(e.path())) out.push_back(e.path());
  std::sort(out.begin(), out.end());
  return out;
}

SlCaptureInfo describe_sl_capture(const fs::path& folder, int projector_width,
                                  int projector_height) {
  std::error_code ec;
  if (!fs::is_directory(folder, ec))
    throw InputError(folder.string(), "", "not a folder (expected a structured-light capture)");
  if (exists_file(folder / "capture.json"))
    return describe_scanclean(folder, projector_width, projector_height);
  if (exists_file(folder / "graycode_00.png"))
    return describe_kamino(folder, projector_width, projector_height);
  throw InputError(folder.string(), "",
                   "not a structured-light capture (expected capture.json, or graycode_00.png of "
                   "the kamino410 layout)");
}

SlCapture::SlCapture() : impl_(std::make_shared<Impl>()) {}

namespace {
std::vector<int> pattern_indices_of(const SlCaptureInfo& info) {
  std::vector<int> idx;
  const int total = static_cast<int>(info.images.size());
  for (int k = 0; k < total; ++k)
    if (k != info.white_index && k != info.black_index) idx.push_back(k);
  return idx;
}

void check_info(const SlCaptureInfo& info) {
  const int total = info.graycode.pattern_count() + 2;
  if (static_cast<int>(info.images.size()) != total)
    throw InputError(
        info.folder.string(), "",
        std::to_string(info.images.size()) + " images, expected " + std::to_string(total));
  if (info.white_index < 0 || info.white_index >= total || info.black_index < 0 ||
      info.black_index >= total || info.white_index == info.black_index)
    throw InputError(info.folder.string(), "", "white/black image indices out of range");
}
}  // namespace

SlCapture SlCapture::load(const SlCaptureInfo& info) {
  check_info(info);
  auto impl = std::make_shared<Impl>();
  impl->info = info;
  impl->pattern_indices = pattern_indices_of(info);
  const int total = static_cast<int>(info.images.size());
  for (int k = 0; k < total; ++k) {
    const fs::path& p = info.images[static_cast<std::size_t>(k)];
    const std::string what = k == info.white_index   ? "white image"
                             : k == info.black_index ? "black image"
                                                     : "pattern image";
    if (!exists_file(p))
      throw InputError(
          p.string(), "",
          "missing (" + what + " " + std::to_string(k) + " of " + std::to_string(total) + ")");
    if (k > 0) {
      // Refuse an image of another size before decoding it (no allocation from its header).
      const auto size = png_size(p);
      if (size && ((*size)[0] != impl->images[0].cols || (*size)[1] != impl->images[0].rows))
        throw InputError(p.string(), "PNG header",
                         "image size " + std::to_string((*size)[0]) + "x" +
                             std::to_string((*size)[1]) + ", expected " +
                             std::to_string(impl->images[0].cols) + "x" +
                             std::to_string(impl->images[0].rows) + " (as image 0)");
    }
    cv::Mat m;
    try {
      m = cv::imread(p.string(), cv::IMREAD_UNCHANGED);
    } catch (const cv::Exception& e) {
      throw InputError(p.string(), "", std::string("cannot decode image: ") + e.err);
    }
    if (m.empty()) throw InputError(p.string(), "", "cannot decode image (" + what + ")");
    if (m.depth() != CV_8U && m.depth() != CV_16U)
      throw InputError(p.string(), "", "expected an 8- or 16-bit image");
    if (m.channels() == 3)
      cv::cvtColor(m, m, cv::COLOR_BGR2GRAY);
    else if (m.channels() == 4)
      cv::cvtColor(m, m, cv::COLOR_BGRA2GRAY);
    else if (m.channels() != 1)
      throw InputError(p.string(), "", "expected a grayscale image");
    if (k > 0) {
      const cv::Mat& first = impl->images[0];
      if (m.size() != first.size())
        throw InputError(p.string(), "",
                         "image size " + std::to_string(m.cols) + "x" + std::to_string(m.rows) +
                             ", expected " + std::to_string(first.cols) + "x" +
                             std::to_string(first.rows) + " (as image 0)");
      if (m.depth() != first.depth())
        throw InputError(p.string(), "",
                         std::string("bit depth ") + (m.depth() == CV_8U ? "8" : "16") +
                             ", expected " + (first.depth() == CV_8U ? "8" : "16") +
                             " (as image 0)");
    }
    impl->images.push_back(m);
  }
  SlCapture c;
  c.impl_ = std::move(impl);
  return c;
}

SlCapture SlCapture::from_images(const SlCaptureInfo& info,
                                 const std::vector<Image<std::uint8_t>>& images) {
  if (images.size() != info.images.size() && !info.images.empty())
    throw InputError(info.folder.string(), "", "image count differs from the description");
  auto impl = std::make_shared<Impl>();
  impl->info = info;
  if (impl->info.images.empty())
    for (std::size_t k = 0; k < images.size(); ++k)
      impl->info.images.push_back("memory:" + std::to_string(k));
  check_info(impl->info);
  impl->pattern_indices = pattern_indices_of(impl->info);
  for (std::size_t k = 0; k < images.size(); ++k) {
    const auto& im = images[k];
    if (im.width != images[0].width || im.height != images[0].height || im.empty())
      throw InputError("memory:" + std::to_string(k), "", "image size differs from image 0");
    cv::Mat m(im.height, im.width, CV_8U);
    std::copy(im.data.begin(), im.data.end(), m.ptr<std::uint8_t>(0));
    impl->images.push_back(m);
  }
  SlCapture c;
  c.impl_ = std::move(impl);
  return c;
}

const SlCaptureInfo& SlCapture::info() const {
  return impl_->info;
}
int SlCapture::width() const {
  return impl_->images.empty() ? 0 : impl_->images[0].cols;
}
int SlCapture::height() const {
  return impl_->images.empty() ? 0 : impl_->images[0].rows;
}
int SlCapture::bit_depth() const {
  return impl_->images.empty() || impl_->images[0].depth() == CV_8U ? 8 : 16;
}

int write_graycode_patterns(const fs::path& folder, int projector_width, int projector_height,
                            int white_threshold, int black_threshold) {
  const GrayCodeLayout layout = graycode_layout(projector_width, projector_height);
  if (white_threshold < 0 || black_threshold < 0) throw OptionError("thresholds must be >= 0");
  const auto pattern =
      cv::structured_light::GrayCodePattern::create(projector_width, projector_height);
  std::vector<cv::Mat> images;
  pattern->generate(images);
  cv::Mat black, white;
  pattern->getImagesForShadowMasks(black, white);
  const int count = static_cast<int>(images.size());
  images.push_back(white);
  images.push_back(black);
  std::error_code ec;
  fs::create_directories(folder / "patterns", ec);
  if (ec) throw IoError((folder / "patterns").string() + ": cannot create folder: " + ec.message());
  const int digits = std::max(3, static_cast<int>(std::to_string(images.size() - 1).size()));
  for (std::size_t k = 0; k < images.size(); ++k) {
    std::vector<unsigned char> png;
    if (!cv::imencode(".png", images[k], png))
      throw IoError("cannot encode pattern " + std::to_string(k) + " as PNG");
    write_file_atomically(folder / "patterns" / index_name(static_cast<int>(k), digits),
                          [&](std::ostream& out) {
                            out.write(reinterpret_cast<const char*>(png.data()),
                                      static_cast<std::streamsize>(png.size()));
                          });
  }
  nlohmann::ordered_json j;
  j["format"] = "scanclean-sl/1";
  j["projector"] = {{"width", projector_width}, {"height", projector_height}};
  j["pattern"] = "graycode";
  j["order"] = "opencv";
  j["count"] = count;
  j["column_bits"] = layout.column_bits;
  j["row_bits"] = layout.row_bits;
  j["white_index"] = count;
  j["black_index"] = count + 1;
  j["image_dir"] = "img";
  j["thresholds"] = {{"white", white_threshold}, {"black", black_threshold}};
  j["note"] =
      "Project patterns/NNN.png in index order and save the camera image of pattern k as "
      "img/NNN.png (same number) in a capture folder holding this file and calib.yml.";
  write_file_atomically(
      folder / "capture.json", [&](std::ostream& out) { out << j.dump(2) << "\n"; }, false);
  return static_cast<int>(images.size());
}

}  // namespace scanclean

#include "scanclean/replay/depth_image_source.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <ctime>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <system_error>

#include "json_input.h"
#include "png16.h"
#include "scanclean/core/errors.h"

namespace scanclean {

namespace fs = std::filesystem;

namespace {

constexpr std::uint64_t kMaxPixels = std::uint64_t{1} << 26;
constexpr std::uintmax_t kMaxImageBytes = std::uintmax_t{1} << 28;  // 256 MiB

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

bool is_depth_extension(const fs::path& p) {
  const std::string e = lower(p.extension().string());
  return e == ".png" || e == ".pgm" || e == ".tif" || e == ".tiff";
}

bool looks_like_colour(const fs::path& p) {
  const std::string n = lower(p.filename().string());
  return n.find("rgb") != std::string::npos || n.find("color") != std::string::npos ||
         n.find("colour") != std::string::npos;
}

enum class Encoding { kTum, kMm, kNyu };

const char* encoding_name(Encoding e) {
  switch (e) {
    case Encoding::kTum:
      return "tum";
    case Encoding::kMm:
      return "mm";
    case Encoding::kNyu:
      return "nyu";
  }
  return "?";
}

//! One decoded 16-bit image. For PGM both byte orders are kept (big-endian = the PGM standard).
struct Raw16 {
  std::string container;                       // "PNG", "PGM", "TIFF"
  Image<std::uint16_t> image;                  // PNG/TIFF: decoded; PGM: big-endian samples
  std::optional<Image<std::uint16_t>> pgm_le;  // PGM only: the same bytes read little-endian
};

//! Binary PGM (P5) with maxval > 255. Every token's byte offset is checked against the file.
Raw16 read_pgm16(const fs::path& file) {
  const std::string name = file.string();
  const std::vector<unsigned char> b = detail::read_file_bytes(file, kMaxImageBytes);
  std::size_t pos = 0;
  if (b.size() < 2 || b[0] != 'P' || b[1] != '5')
    throw InputError(name, byte_place(0), "not a binary PGM (expected magic \"P5\")");
  pos = 2;
  auto skip_space = [&] {
    for (;;) {
      while (pos < b.size() && std::isspace(b[pos])) ++pos;
      if (pos < b.size() && b[pos] == '#') {
        while (pos < b.size() && b[pos] != '\n') ++pos;
        continue;
      }
      return;
    }
  };
  auto number = [&](const char* what) -> std::uint64_t {
    skip_space();
    const std::size_t start = pos;
    std::uint64_t v = 0;
    while (pos < b.size() && std::isdigit(b[pos]) && pos - start < 9) v = v * 10 + (b[pos++] - '0');
    if (pos == start || (pos < b.size() && std::isdigit(b[pos])))
      throw InputError(name, byte_place(start),
                       std::string("PGM header: expected the ") + what + " (a positive integer)");
    return v;
  };
  const std::uint64_t w = number("width"), h = number("height"), maxval = number("maxval");
  if (w == 0 || h == 0 || w * h > kMaxPixels)
    throw InputError(name, "PGM header",
                     "implausible size " + std::to_string(w) + "x" + std::to_string(h));
  if (maxval == 0 || maxval > 65535)
    throw InputError(name, "PGM header", "maxval must be 1..65535, got " + std::to_string(maxval));
  if (maxval <= 255)
    throw InputError(name, "PGM header",
                     "8-bit PGM (maxval " + std::to_string(maxval) +
                         "): a depth image must have 16-bit samples (maxval > 255)");
  if (pos >= b.size() || !std::isspace(b[pos]))
    throw InputError(name, byte_place(pos), "PGM header: expected one whitespace after maxval");
  ++pos;
  const std::uint64_t need = w * h * 2;
  if (b.size() - pos < need)
    throw InputError(name, byte_place(b.size()),
                     "truncated PGM: " + std::to_string(w) + "x" + std::to_string(h) +
                         " 16-bit samples need " + std::to_string(need) +
                         " bytes after the header, " + std::to_string(b.size() - pos) + " present");
  Raw16 r;
  r.container = "PGM";
  r.image = Image<std::uint16_t>(static_cast<int>(w), static_cast<int>(h));
  Image<std::uint16_t> le(static_cast<int>(w), static_cast<int>(h));
  for (std::size_t k = 0; k < r.image.data.size(); ++k) {
    const unsigned char hi = b[pos + 2 * k], lo = b[pos + 2 * k + 1];
    r.image.data[k] = static_cast<std::uint16_t>((hi << 8) | lo);
    le.data[k] = static_cast<std::uint16_t>((lo << 8) | hi);
  }
  r.pgm_le = std::move(le);
  return r;
}

Raw16 read_tiff16(const fs::path& file) {
  const std::string name = file.string();
  const std::vector<unsigned char> bytes = detail::read_file_bytes(file, kMaxImageBytes);
  // The size the header declares is checked against the file before OpenCV allocates: the
  // pixels (16 bits each) cannot be compressed better than about 1032:1 (deflate; 1100 allowed).
  const auto size = detail::tiff_size(bytes);
  if (!size)
    throw InputError(name, "TIFF header",
                     "no image width and height found (not a classic TIFF, or corrupt)");
  if (size->first * size->second > kMaxPixels)
    throw InputError(name, "TIFF header",
                     "implausible image size " + std::to_string(size->first) + "x" +
                         std::to_string(size->second));
  if (size->first * size->second * 2 > 1100 * static_cast<std::uint64_t>(bytes.size()))
    throw InputError(name, "TIFF header",
                     std::to_string(size->first) + "x" + std::to_string(size->second) +
                         " 16-bit pixels cannot be held in " + std::to_string(bytes.size()) +
                         " bytes (truncated file or a lying header)");
  cv::Mat mat;
  try {
    mat = cv::imdecode(bytes, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    throw InputError(name, "", "cannot decode TIFF: " + e.msg);
  }
  if (mat.empty()) throw InputError(name, "", "cannot decode the image (corrupt or unsupported)");
  if (mat.type() != CV_16UC1)
    throw InputError(name, "",
                     "decoded to " + std::to_string(mat.channels()) + " channel(s) of " +
                         std::to_string(mat.elemSize1() * 8) +
                         " bits; a depth image must have one 16-bit channel");
  Raw16 r;
  r.container = "TIFF";
  r.image = Image<std::uint16_t>(mat.cols, mat.rows);
  for (int v = 0; v < mat.rows; ++v) {
    const auto* row = mat.ptr<std::uint16_t>(v);
    std::copy(row, row + mat.cols,
              r.image.data.begin() + static_cast<std::ptrdiff_t>(v) * mat.cols);
  }
  return r;
}

Raw16 read_raw16(const fs::path& file) {
  const std::string e = lower(file.extension().string());
  if (e == ".pgm") return read_pgm16(file);
  if (e == ".tif" || e == ".tiff") return read_tiff16(file);
  if (e == ".png") {
    Raw16 r;
    r.container = "PNG";
    r.image = detail::read_png16(file, 0, 0, "depth");
    return r;
  }
  throw InputError(
      file.string(), "",
      "unsupported depth image extension \"" + e + "\" (expected .png .pgm .tif .tiff)");
}

//! Mean absolute difference of horizontally adjacent samples: real depth is piecewise smooth,
//! so the wrong byte order (low byte promoted to high) gives a far larger value.
double roughness(const Image<std::uint16_t>& img) {
  double sum = 0;
  std::size_t n = 0;
  for (int v = 0; v < img.height; ++v)
    for (int u = 0; u + 1 < img.width; ++u) {
      sum += std::abs(static_cast<int>(img(u + 1, v)) - static_cast<int>(img(u, v)));
      ++n;
    }
  return n ? sum / static_cast<double>(n) : 0.0;
}

std::uint16_t max_value(const Image<std::uint16_t>& img) {
  return img.data.empty() ? 0 : *std::max_element(img.data.begin(), img.data.end());
}

struct Sidecar {
  fs::path file;
  std::optional<Intrinsics> K;
  std::optional<Encoding> encoding;
  std::string noise_model;
};

std::optional<Encoding> parse_encoding(const std::string& s) {
  if (s == "tum") return Encoding::kTum;
  if (s == "mm") return Encoding::kMm;
  if (s == "nyu") return Encoding::kNyu;
  return std::nullopt;
}

Sidecar read_sidecar(const fs::path& file) {
  using nlohmann::json;
  const std::string name = file.string();
  const std::vector<unsigned char> bytes = detail::read_file_bytes(file, 1 << 20);
  const json j = detail::parse_json_input(std::string(bytes.begin(), bytes.end()), name);
  if (!j.is_object()) throw InputError(name, "", "expected a JSON object");
  auto num = [&](const char* key) {
    if (!j.contains(key)) throw InputError(name, std::string("field ") + key, "missing");
    if (!j[key].is_number())
      throw InputError(name, std::string("field ") + key,
                       "expected a number, got " + j[key].dump());
    return j[key].get<double>();
  };
  auto opt_int = [&](const char* key) {
    if (!j.contains(key)) return 0;
    if (!j[key].is_number_integer() || j[key].get<std::int64_t>() <= 0 ||
        j[key].get<std::int64_t>() > 32768)
      throw InputError(name, std::string("field ") + key,
                       "expected a positive integer, got " + j[key].dump());
    return static_cast<int>(j[key].get<std::int64_t>());
  };
  Sidecar s;
  s.file = file;
  Intrinsics K;
  if (j.contains("intrinsic_matrix")) {  // Open3D PinholeCameraIntrinsic: column-major 3x3
    const json& m = j["intrinsic_matrix"];
    if (!m.is_array() || m.size() != 9 ||
        !std::all_of(m.begin(), m.end(), [](const json& x) { return x.is_number(); }))
      throw InputError(name, "field intrinsic_matrix", "expected 9 numbers (column-major 3x3)");
    K.fx = m[0].get<double>();
    K.fy = m[4].get<double>();
    K.cx = m[6].get<double>();
    K.cy = m[7].get<double>();
  } else if (j.contains("fx") || j.contains("fy") || j.contains("cx") || j.contains("cy")) {
    K.fx = num("fx");
    K.fy = num("fy");
    K.cx = num("cx");
    K.cy = num("cy");
  }
  // A sidecar may hold only the format (intrinsics then come from the command line).
  const bool has_k = j.contains("intrinsic_matrix") || j.contains("fx") || j.contains("fy") ||
                     j.contains("cx") || j.contains("cy");
  if (has_k && (!(K.fx > 0) || !(K.fy > 0)))
    throw InputError(name, "field fx/fy", "focal lengths must be positive");
  K.width = opt_int("width");
  K.height = opt_int("height");
  if (j.contains("dist")) {
    const json& d = j["dist"];
    if (!d.is_array() || d.size() != 5 ||
        !std::all_of(d.begin(), d.end(), [](const json& x) { return x.is_number(); }))
      throw InputError(name, "field dist", "expected 5 numbers (k1 k2 p1 p2 k3)");
    for (int k = 0; k < 5; ++k) K.dist[k] = d[k].get<double>();
  }
  K.source = "calibration";
  if (has_k) s.K = K;
  if (j.contains("format")) {
    if (!j["format"].is_string() || !parse_encoding(j["format"].get<std::string>()))
      throw InputError(name, "field format",
                       "expected \"tum\", \"mm\" or \"nyu\", got " + j["format"].dump());
    s.encoding = parse_encoding(j["format"].get<std::string>());
  }
  if (j.contains("depth_scale")) {
    const double scale = num("depth_scale");
    std::optional<Encoding> e;
    if (scale == 5000) e = Encoding::kTum;
    if (scale == 1000) e = Encoding::kMm;
    if (!e)
      throw InputError(name, "field depth_scale",
                       "expected 5000 (TUM, counts per metre) or 1000 (millimetres), got " +
                           j["depth_scale"].dump());
    if (s.encoding && *s.encoding != *e)
      throw InputError(
          name, "field depth_scale",
          "contradicts field format \"" + std::string(encoding_name(*s.encoding)) + "\"");
    s.encoding = e;
  }
  if (j.contains("noise_model")) {
    if (!j["noise_model"].is_string())
      throw InputError(name, "field noise_model", "expected a string");
    s.noise_model = j["noise_model"].get<std::string>();
    if (s.noise_model != "nguyen2012" && s.noise_model != "structured-light" &&
        s.noise_model != "none")
      throw InputError(name, "field noise_model",
                       "expected \"nguyen2012\", \"structured-light\" or \"none\"");
  }
  return s;
}

//! intrinsics.json beside the images, else in the parent folder; Open3D's camera_intrinsic.json
//! and camera_primesense.json are accepted under the same rule.
std::optional<fs::path> find_sidecar(const fs::path& images) {
  std::error_code ec;
  fs::path image_dir = fs::absolute(images, ec).lexically_normal();
  if (ec || image_dir.empty()) image_dir = images;
  if (image_dir.has_filename() == false) image_dir = image_dir.parent_path();  // trailing '/'
  for (const fs::path& dir : {image_dir, image_dir.parent_path()}) {
    if (dir.empty()) continue;
    for (const char* n : {"intrinsics.json", "camera_intrinsic.json", "camera_primesense.json"})
      if (fs::is_regular_file(dir / n, ec)) return dir / n;
  }
  return std::nullopt;
}

}  // namespace

std::optional<std::int64_t> timestamp_from_name(const std::string& stem) {
  // TUM: the whole stem is a decimal number of seconds (plausible UNIX time).
  {
    std::size_t dot = stem.find('.');
    bool digits = !stem.empty() && dot != std::string::npos && dot > 0 && dot + 1 < stem.size();
    for (std::size_t k = 0; digits && k < stem.size(); ++k)
      if (k != dot && !std::isdigit(static_cast<unsigned char>(stem[k]))) digits = false;
    if (digits && dot >= 9 && dot <= 10) {
      const std::int64_t sec = std::stoll(stem.substr(0, dot));
      std::string frac = stem.substr(dot + 1, 6);
      frac.resize(6, '0');
      return sec * 1'000'000 + std::stoll(frac);
    }
  }
  // PCL grabber: YYYYMMDDTHHMMSS.ffffff somewhere in the name.
  for (std::size_t k = 0; k + 22 <= stem.size(); ++k) {
    auto dig = [&](std::size_t a, std::size_t n) {
      for (std::size_t i = a; i < a + n; ++i)
        if (!std::isdigit(static_cast<unsigned char>(stem[i]))) return false;
      return true;
    };
    if (!(dig(k, 8) && stem[k + 8] == 'T' && dig(k + 9, 6) && stem[k + 15] == '.' &&
          dig(k + 16, 6)))
      continue;
    std::tm tm{};
    tm.tm_year = std::stoi(stem.substr(k, 4)) - 1900;
    tm.tm_mon = std::stoi(stem.substr(k + 4, 2)) - 1;
    tm.tm_mday = std::stoi(stem.substr(k + 6, 2));
    tm.tm_hour = std::stoi(stem.substr(k + 9, 2));
    tm.tm_min = std::stoi(stem.substr(k + 11, 2));
    tm.tm_sec = std::stoi(stem.substr(k + 13, 2));
    const std::time_t t = timegm(&tm);
    return static_cast<std::int64_t>(t) * 1'000'000 + std::stoll(stem.substr(k + 16, 6));
  }
  return std::nullopt;
}

namespace {

//! The colour image that belongs to a depth image, if there is one: in a depth/ folder, the
//! file of the same stem in a sibling color/, colour/ or rgb/ folder (Redwood, slambook);
//! otherwise the file whose name has "color", "colour" or "rgb" where the depth's has "depth"
//! (Open3D's TUM_depth.png / TUM_color.png, NYU_depth.pgm / NYU_color.ppm).
std::optional<fs::path> colour_beside(const fs::path& depth) {
  static const char* const kExt[] = {".png",  ".jpg", ".jpeg", ".ppm",
                                     ".tiff", ".tif", ".PNG",  ".JPG"};
  std::error_code ec;
  const fs::path dir = depth.parent_path();
  if (lower(dir.filename().string()) == "depth") {
    for (const char* sub : {"color", "colour", "rgb"})
      for (const char* e : kExt) {
        const fs::path c = dir.parent_path() / sub / (depth.stem().string() + e);
        if (fs::is_regular_file(c, ec)) return c;
      }
  }
  const std::string name = depth.stem().string();
  const std::string low = lower(name);
  const auto at = low.find("depth");
  if (at == std::string::npos) return std::nullopt;
  for (const char* word : {"color", "colour", "rgb"})
    for (const char* e : kExt) {
      const fs::path c = dir / (name.substr(0, at) + word + name.substr(at + 5) + e);
      if (fs::is_regular_file(c, ec)) return c;
    }
  return std::nullopt;
}

//! TUM RGB-D sequences: depth/<t>.png and rgb/<t'>.png are taken at different instants, so
//! their names differ. Each depth image gets the colour image of the sibling rgb/ (or color/)
//! folder nearest to it in time, when that is within 20 ms (the dataset's association rule; its
//! depth is registered to the colour camera). Empty unless every depth image has one.
std::vector<fs::path> colour_by_timestamp(const std::vector<fs::path>& depth_files) {
  constexpr std::int64_t kMaxDifferenceUs = 20'000;
  if (depth_files.empty()) return {};
  const fs::path dir = depth_files.front().parent_path();
  if (lower(dir.filename().string()) != "depth") return {};
  std::error_code ec;
  std::vector<std::pair<std::int64_t, fs::path>> colour;  // by time
  for (const char* sub : {"rgb", "color", "colour"}) {
    const fs::path cdir = dir.parent_path() / sub;
    if (!fs::is_directory(cdir, ec)) continue;
    for (const auto& e : fs::directory_iterator(cdir, ec)) {
      const std::string ext = lower(e.path().extension().string());
      if (!e.is_regular_file(ec) ||
          (ext != ".png" && ext != ".jpg" && ext != ".jpeg" && ext != ".tiff" && ext != ".tif"))
        continue;
      if (const auto t = timestamp_from_name(e.path().stem().string()))
        colour.emplace_back(*t, e.path());
    }
    if (!colour.empty()) break;
  }
  if (colour.empty()) return {};
  std::sort(colour.begin(), colour.end());
  std::vector<fs::path> out;
  out.reserve(depth_files.size());
  for (const fs::path& d : depth_files) {
    if (d.parent_path() != dir) return {};
    const auto t = timestamp_from_name(d.stem().string());
    if (!t) return {};
    auto it = std::lower_bound(colour.begin(), colour.end(), *t,
                               [](const auto& c, std::int64_t v) { return c.first < v; });
    std::int64_t best = std::numeric_limits<std::int64_t>::max();
    const fs::path* nearest = nullptr;
    const auto consider = [&](const std::pair<std::int64_t, fs::path>& c) {
      const std::int64_t dt = c.first > *t ? c.first - *t : *t - c.first;
      if (dt < best) {
        best = dt;
        nearest = &c.second;
      }
    };
    if (it != colour.end()) consider(*it);
    if (it != colour.begin()) consider(*std::prev(it));
    if (!nearest || best > kMaxDifferenceUs) return {};
    out.push_back(*nearest);
  }
  return out;
}

class DepthImageSource final : public RangeSource {
 public:
  DepthImageSource(fs::path path, std::vector<fs::path> files, DepthImageOptions options)
      : path_(std::move(path)), files_(std::move(files)), options_(std::move(options)) {}

  void open() override {
    next_ = 0;
    fs::path dir = files_.front().parent_path();  // the images' folder (maybe <folder>/depth)
    if (dir.empty()) dir = ".";
    std::optional<Sidecar> sidecar;
    if (auto f = find_sidecar(dir)) sidecar = read_sidecar(*f);

    // Intrinsics: the command line wins over the sidecar.
    if (options_.K) {
      K_ = *options_.K;
      k_origin_ = "command line";
    } else if (sidecar && sidecar->K) {
      K_ = *sidecar->K;
      k_origin_ = sidecar->file.string();
    } else {
      throw OptionError(
          "no camera intrinsics for " + path_.string() +
          ": depth images carry none. Pass them on the command line (--fx --fy --cx --cy, pixels) "
          "or put a sidecar file intrinsics.json beside the images, e.g. "
          "{\"fx\": 525, \"fy\": 525, \"cx\": 319.5, \"cy\": 239.5, \"width\": 640, "
          "\"height\": 480, \"format\": \"tum\"} (see recordings/README.md)");
    }

    // Decide the encoding from the first image.
    Raw16 first = read_raw16(files_.front());
    std::string why;
    if (options_.format != "auto") {
      encoding_ = *parse_encoding(options_.format);
      why = "format " + options_.format + " (option)";
    } else if (sidecar && sidecar->encoding) {
      encoding_ = *sidecar->encoding;
      why = std::string("format ") + encoding_name(encoding_) + " (from " +
            sidecar->file.filename().string() + ")";
    } else {
      why = decide_auto(first);
    }
    pgm_little_endian_ = encoding_ == Encoding::kNyu;
    if (first.container == "PGM" && options_.format == "auto" && !(sidecar && sidecar->encoding))
      pgm_little_endian_ = pgm_le_auto_;
    if (encoding_ == Encoding::kTum && first.container != "PNG")
      throw InputError(files_.front().string(), "",
                       "format tum is a 16-bit PNG encoding; this file is " + first.container);
    if (encoding_ == Encoding::kNyu && first.container != "PGM")
      throw InputError(
          files_.front().string(), "",
          "format nyu is the NYU Depth v2 PGM encoding; this file is " + first.container);

    width_ = first.image.width;
    height_ = first.image.height;
    if (K_.width == 0 && K_.height == 0) {
      K_.width = width_;
      K_.height = height_;
    }
    if (K_.width != width_ || K_.height != height_)
      throw InputError(files_.front().string(), "",
                       "image is " + std::to_string(width_) + "x" + std::to_string(height_) +
                           ", the intrinsics (" + k_origin_ + ") are for " +
                           std::to_string(K_.width) + "x" + std::to_string(K_.height));

    std::string noise = options_.noise_model;
    if (noise.empty() && sidecar) noise = sidecar->noise_model;
    if (noise.empty()) noise = encoding_ == Encoding::kMm ? "none" : "nguyen2012";

    // Timestamps from the names when all have one and they increase.
    timestamps_us_.clear();
    for (const fs::path& f : files_) {
      auto t = timestamp_from_name(f.stem().string());
      if (!t || (!timestamps_us_.empty() && *t <= timestamps_us_.back())) {
        timestamps_us_.clear();
        break;
      }
      timestamps_us_.push_back(*t);
    }

    // Colour images beside the depth images: used when every depth image has one of its size.
    colour_files_.clear();
    std::string colour_note;
    for (const fs::path& f : files_) {
      auto c = colour_beside(f);
      if (!c) {
        colour_files_.clear();
        break;
      }
      colour_files_.push_back(*c);
    }
    if (colour_files_.empty()) colour_files_ = colour_by_timestamp(files_);
    std::vector<std::string> warnings;
    if (!colour_files_.empty()) {
      const auto rgb = detail::read_rgb_image(colour_files_.front());
      if (rgb.width != width_ || rgb.height != height_) {
        warnings.push_back(colour_files_.front().string() + ": colour image is " +
                           std::to_string(rgb.width) + "x" + std::to_string(rgb.height) +
                           ", the depth " + std::to_string(width_) + "x" + std::to_string(height_) +
                           " (not registered); colour not used");
        colour_files_.clear();
      } else {
        colour_note = "; colour from " + colour_files_.front().filename().string() +
                      (colour_files_.size() > 1 ? " ..." : "");
        if (encoding_ == Encoding::kNyu)
          warnings.push_back(colour_files_.front().string() +
                             ": NYU raw colour is not registered to the depth camera; the "
                             "points' colours are offset by a few pixels");
      }
    }

    SourceInfo info;
    info.warnings = std::move(warnings);
    info.uri = path_.string();
    info.kind = "depth-images";
    info.name = std::string(encoding_name(encoding_)) + ": " + describe() + "; " + why +
                "; intrinsics from " + k_origin_ + colour_note;
    info.is_live = false;
    info.frame_count = files_.size();
    info.K = K_;
    info.depth_unit_m = unit_m();
    info.noise_model = noise;
    info_ = std::move(info);
    first_ = std::move(first);
  }

  ReadStatus next(RangeFrame& frame, std::chrono::milliseconds) override {
    if (width_ == 0) {
      error_ = "next() called before open()";
      return ReadStatus::kError;
    }
    if (next_ >= files_.size()) return ReadStatus::kEndOfStream;
    const fs::path& file = files_[next_];
    Raw16 raw = (next_ == 0 && first_) ? std::move(*first_) : read_raw16(file);
    first_.reset();
    const Image<std::uint16_t>& src =
        (raw.container == "PGM" && pgm_little_endian_) ? *raw.pgm_le : raw.image;
    if (src.width != width_ || src.height != height_)
      throw InputError(file.string(), "",
                       "image is " + std::to_string(src.width) + "x" + std::to_string(src.height) +
                           ", the sequence's first image is " + std::to_string(width_) + "x" +
                           std::to_string(height_));
    RangeFrame f;
    f.index = next_;
    f.device_ts_us = timestamps_us_.empty()
                         ? static_cast<std::int64_t>(std::llround(static_cast<double>(next_) *
                                                                  options_.frame_period_s * 1e6))
                         : timestamps_us_[next_];
    f.host_ts_ns = f.device_ts_us * 1000;
    f.depth_unit_m = unit_m();
    f.K = K_;
    if (encoding_ == Encoding::kNyu) {
      f.depth = Image<std::uint16_t>(width_, height_);
      for (std::size_t k = 0; k < src.data.size(); ++k) f.depth.data[k] = nyu_to_mm(src.data[k]);
    } else {
      f.depth = src;
    }
    if (!colour_files_.empty()) {
      auto rgb = detail::read_rgb_image(colour_files_[next_]);
      if (rgb.width != width_ || rgb.height != height_)
        throw InputError(colour_files_[next_].string(), "",
                         "colour image is " + std::to_string(rgb.width) + "x" +
                             std::to_string(rgb.height) + ", the depth image " +
                             std::to_string(width_) + "x" + std::to_string(height_));
      f.color = std::move(rgb);
    }
    frame = std::move(f);
    ++next_;
    return ReadStatus::kOk;
  }

  SourceInfo info() const override { return info_; }
  void close() override {
    first_.reset();
    width_ = height_ = 0;
  }
  std::string last_error() const override { return error_; }

 private:
  //! NYU raw Kinect disparity -> millimetres (Open3D's RGBDImageFactory formula); 0 = invalid.
  static std::uint16_t nyu_to_mm(std::uint16_t raw) {
    if (raw >= 2047) return 0;
    const double denom = 1092.5 - raw;
    if (denom <= 0) return 0;
    const double mm = 351.3 / denom * 1000.0;
    if (!(mm < 65535.5)) return 0;
    return static_cast<std::uint16_t>(std::lround(mm));
  }

  double unit_m() const { return encoding_ == Encoding::kTum ? 1.0 / 5000.0 : 0.001; }

  std::string describe() const {
    switch (encoding_) {
      case Encoding::kTum:
        return "TUM RGB-D 16-bit PNG, metres = value / 5000 (unit 0.2 mm)";
      case Encoding::kMm:
        return "16-bit depth in millimetres (unit 1 mm)";
      case Encoding::kNyu:
        return "NYU Depth v2 raw disparity (little-endian PGM), depth_m = 351.3 / (1092.5 - raw), "
               "converted to millimetres";
    }
    return "";
  }

  std::string decide_auto(const Raw16& first) {
    const std::string name = files_.front().filename().string();
    if (first.container == "TIFF") {
      encoding_ = Encoding::kMm;
      return "auto: 16-bit TIFF is read as millimetres (PCL ImageGrabber convention)";
    }
    if (first.container == "PNG") {
      const std::uint16_t mx = max_value(first.image);
      if (mx > 10000) {
        encoding_ = Encoding::kTum;
        return "auto: " + name + " has values up to " + std::to_string(mx) +
               " > 10000 (the PS1080 maximum in millimetres), so TUM 1/5000 m; pass format mm to "
               "override";
      }
      encoding_ = Encoding::kMm;
      return "auto: " + name + " has values up to " + std::to_string(mx) +
             " <= 10000, so millimetres; pass format tum for TUM-encoded files";
    }
    // PGM: pick the byte order under which the image is smooth, then the encoding by range.
    const double r_be = roughness(first.image), r_le = roughness(*first.pgm_le);
    std::ostringstream why;
    why << "auto: " << name << " is smoother read " << (r_le < r_be ? "little" : "big")
        << "-endian (mean |horizontal step| " << (r_le < r_be ? r_le : r_be) << " vs "
        << (r_le < r_be ? r_be : r_le) << ")";
    if (r_le < r_be) {
      const std::uint16_t mx = max_value(*first.pgm_le);
      pgm_le_auto_ = true;
      if (mx <= 2047) {
        encoding_ = Encoding::kNyu;
        why << " with values up to " << mx << " <= 2047 (11-bit Kinect disparity), so NYU";
      } else {
        encoding_ = Encoding::kMm;
        why << " with values up to " << mx << " > 2047, so millimetres (little-endian)";
      }
    } else {
      pgm_le_auto_ = false;
      encoding_ = Encoding::kMm;
      why << ", so standard PGM in millimetres";
    }
    why << "; pass format mm or nyu to override";
    return why.str();
  }

  fs::path path_;
  std::vector<fs::path> files_;
  DepthImageOptions options_;
  Intrinsics K_;
  std::string k_origin_;
  Encoding encoding_ = Encoding::kMm;
  bool pgm_little_endian_ = false;
  bool pgm_le_auto_ = false;
  int width_ = 0, height_ = 0;
  std::vector<std::int64_t> timestamps_us_;
  std::vector<fs::path> colour_files_;  //!< per depth image; empty = no colour
  std::optional<Raw16> first_;
  std::size_t next_ = 0;
  SourceInfo info_;
  std::string error_;
};

}  // namespace

void validate(const DepthImageOptions& o) {
  if (o.format != "auto" && !parse_encoding(o.format))
    throw OptionError("depth image format \"" + o.format +
                      "\" is not one of auto, tum (PNG, 1/5000 m), mm (millimetres), nyu (NYU "
                      "raw disparity PGM)");
  if (o.K && (!(o.K->fx > 0) || !(o.K->fy > 0)))
    throw OptionError("intrinsics: --fx and --fy must be positive, got " + std::to_string(o.K->fx) +
                      " and " + std::to_string(o.K->fy));
  if (o.K && (o.K->width < 0 || o.K->height < 0))
    throw OptionError("intrinsics: width and height must not be negative");
  if (!o.noise_model.empty() && o.noise_model != "nguyen2012" &&
      o.noise_model != "structured-light" && o.noise_model != "none")
    throw OptionError("noise model \"" + o.noise_model +
                      "\" is not one of nguyen2012, structured-light, none");
  if (!(o.frame_period_s > 0))
    throw OptionError("frame period must be positive (seconds), got " +
                      std::to_string(o.frame_period_s));
}

bool natural_less(const std::string& a, const std::string& b) {
  std::size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    const bool da = std::isdigit(static_cast<unsigned char>(a[i]));
    const bool db = std::isdigit(static_cast<unsigned char>(b[j]));
    if (da && db) {
      std::size_t ei = i, ej = j;
      while (ei < a.size() && std::isdigit(static_cast<unsigned char>(a[ei]))) ++ei;
      while (ej < b.size() && std::isdigit(static_cast<unsigned char>(b[ej]))) ++ej;
      std::size_t si = i, sj = j;
      while (si + 1 < ei && a[si] == '0') ++si;  // ignore leading zeros
      while (sj + 1 < ej && b[sj] == '0') ++sj;
      if (ei - si != ej - sj) return ei - si < ej - sj;
      const int c = a.compare(si, ei - si, b, sj, ej - sj);
      if (c != 0) return c < 0;
      i = ei;
      j = ej;
    } else {
      if (a[i] != b[j]) return a[i] < b[j];
      ++i;
      ++j;
    }
  }
  if ((a.size() - i) != (b.size() - j)) return a.size() - i < b.size() - j;
  return a < b;  // equal under the natural order: fall back to plain order (e.g. "01" vs "1")
}

std::vector<fs::path> list_depth_images(const fs::path& p) {
  std::error_code ec;
  if (fs::is_regular_file(p, ec)) {
    if (!is_depth_extension(p))
      throw InputError(p.string(), "",
                       "not a depth image (expected a .png, .pgm, .tif or .tiff file)");
    return {p};
  }
  if (!fs::is_directory(p, ec)) throw InputError(p.string(), "", "no such file or folder");
  auto scan = [](const fs::path& dir) {
    std::vector<fs::path> out;
    std::error_code e;
    for (const auto& entry : fs::directory_iterator(dir, e)) {
      const fs::path& f = entry.path();
      if (!entry.is_regular_file(e) || !is_depth_extension(f) || looks_like_colour(f)) continue;
      if (!f.filename().empty() && f.filename().string()[0] == '.') continue;  // hidden / temp
      out.push_back(f);
    }
    std::sort(out.begin(), out.end(), [](const fs::path& a, const fs::path& b) {
      return natural_less(a.filename().string(), b.filename().string());
    });
    return out;
  };
  std::vector<fs::path> files = scan(p);
  if (files.empty() && fs::is_directory(p / "depth", ec)) files = scan(p / "depth");
  if (files.empty())
    throw InputError(p.string(), "",
                     "holds no depth image (.png .pgm .tif .tiff, names without rgb/color), nor "
                     "a depth/ subfolder with some");
  return files;
}

std::unique_ptr<RangeSource> make_depth_image_source(const fs::path& file_or_folder,
                                                     const DepthImageOptions& options) {
  validate(options);
  return std::make_unique<DepthImageSource>(file_or_folder, list_depth_images(file_or_folder),
                                            options);
}

}  // namespace scanclean

#include "scanclean/drivers/sl_calibration.h"

#include <Eigen/Dense>
#include <cmath>
#include <opencv2/core.hpp>
#include <sstream>
#include <vector>

#include "scanclean/core/atomic_file.h"
#include "scanclean/core/errors.h"

namespace scanclean {
namespace {

std::string describe_shape(const cv::Mat& m) {
  return std::to_string(m.rows) + "x" + std::to_string(m.cols);
}

class CalibReader {
 public:
  CalibReader(const std::filesystem::path& file, cv::FileStorage& fs) : file_(file), fs_(fs) {}

  bool has(const char* name) const { return !fs_[name].empty(); }

  cv::Mat matrix(const char* name, bool required = true) const {
    cv::FileNode node = fs_[name];
    if (node.empty()) {
      if (required)
        throw InputError(file_.string(), std::string("field '") + name + "'", "missing");
      return {};
    }
    cv::Mat m;
    try {
      if (node.isSeq()) {
        std::vector<double> v;
        node >> v;
        m = cv::Mat(v, true).reshape(1, 1);
      } else {
        node >> m;
      }
    } catch (const cv::Exception&) {
      m = cv::Mat();
    }
    if (m.empty())
      throw InputError(file_.string(), std::string("field '") + name + "'",
                       "expected a numeric matrix");
    m.convertTo(m, CV_64F);
    for (int r = 0; r < m.rows; ++r)
      for (int c = 0; c < m.cols; ++c)
        if (!std::isfinite(m.at<double>(r, c)))
          throw InputError(file_.string(), std::string("field '") + name + "'",
                           "contains a non-finite value");
    return m;
  }

  Eigen::Matrix3d mat3(const char* name) const {
    const cv::Mat m = matrix(name);
    if (m.rows != 3 || m.cols != 3)
      throw InputError(file_.string(), std::string("field '") + name + "'",
                       "expected a 3x3 matrix, got " + describe_shape(m));
    Eigen::Matrix3d e;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) e(r, c) = m.at<double>(r, c);
    return e;
  }

  Eigen::Vector3d vec3(const char* name) const {
    const cv::Mat m = matrix(name);
    if (m.total() != 3)
      throw InputError(file_.string(), std::string("field '") + name + "'",
                       "expected 3 values, got " + describe_shape(m));
    const cv::Mat f = m.reshape(1, 3);
    return {f.at<double>(0), f.at<double>(1), f.at<double>(2)};
  }

  std::array<double, 5> distortion(const char* name) const {
    const cv::Mat m = matrix(name);
    const std::size_t n = m.total();
    if (n != 4 && n != 5 && n != 8 && n != 12 && n != 14)
      throw InputError(
          file_.string(), std::string("field '") + name + "'",
          "expected 4, 5, 8, 12 or 14 distortion coefficients, got " + describe_shape(m));
    const cv::Mat f = m.reshape(1, static_cast<int>(n));
    std::array<double, 5> d{};
    for (std::size_t i = 0; i < std::min<std::size_t>(n, 5); ++i)
      d[i] = f.at<double>(static_cast<int>(i));
    for (std::size_t i = 5; i < n; ++i)
      if (f.at<double>(static_cast<int>(i)) != 0.0)
        throw InputError(file_.string(), std::string("field '") + name + "'",
                         "only the 5-coefficient model (k1 k2 p1 p2 k3) is supported; "
                         "coefficient " +
                             std::to_string(i) + " is not zero");
    return d;
  }

  //! Two positive integers, in the file's order.
  std::array<int, 2> size2(const char* name) const {
    const cv::Mat m = matrix(name);
    if (m.total() != 2)
      throw InputError(file_.string(), std::string("field '") + name + "'",
                       "expected 2 values, got " + describe_shape(m));
    const cv::Mat f = m.reshape(1, 2);
    std::array<int, 2> out{};
    for (int i = 0; i < 2; ++i) {
      const double v = f.at<double>(i);
      if (v < 1 || v > 65535 || v != std::floor(v))
        throw InputError(file_.string(), std::string("field '") + name + "'",
                         "expected positive integer sizes");
      out[static_cast<std::size_t>(i)] = static_cast<int>(v);
    }
    return out;
  }

  double scalar(const char* name, double fallback) const {
    cv::FileNode node = fs_[name];
    if (node.empty()) return fallback;
    if (!node.isReal() && !node.isInt())
      throw InputError(file_.string(), std::string("field '") + name + "'", "expected a number");
    return static_cast<double>(node);
  }

  std::string string(const char* name) const {
    cv::FileNode node = fs_[name];
    if (node.empty()) return {};
    if (!node.isString())
      throw InputError(file_.string(), std::string("field '") + name + "'", "expected a string");
    return static_cast<std::string>(node);
  }

  void intrinsics(const char* name, Intrinsics& K) const {
    const Eigen::Matrix3d m = mat3(name);
    K.fx = m(0, 0);
    K.fy = m(1, 1);
    K.cx = m(0, 2);
    K.cy = m(1, 2);
    K.source = "calibration";
    if (!(K.fx > 0) || !(K.fy > 0) || m(1, 0) != 0 || m(2, 0) != 0 || m(2, 1) != 0 ||
        std::abs(m(2, 2) - 1) > 1e-9)
      throw InputError(file_.string(), std::string("field '") + name + "'",
                       "expected a camera matrix [fx 0 cx; 0 fy cy; 0 0 1] with fx, fy > 0");
    if (std::abs(m(0, 1)) > 1e-9 * K.fx)
      throw InputError(file_.string(), std::string("field '") + name + "'",
                       "a skewed camera matrix is not supported");
  }

 private:
  const std::filesystem::path& file_;
  cv::FileStorage& fs_;
};

double unit_to_metres(const std::filesystem::path& file, const std::string& unit) {
  if (unit == "m") return 1.0;
  if (unit == "cm") return 0.01;
  if (unit == "mm") return 0.001;
  if (unit == "um") return 1e-6;
  throw InputError(file.string(), "field 'units'",
                   "expected \"m\", \"cm\", \"mm\" or \"um\", got \"" + unit + "\"");
}

}  // namespace

SlCalibration read_sl_calibration(const std::filesystem::path& file) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(file, ec))
    throw InputError(file.string(), "", "calibration file not found");
  cv::FileStorage fs;
  try {
    if (!fs.open(file.string(), cv::FileStorage::READ))
      throw InputError(file.string(), "", "not an OpenCV FileStorage file (YAML/XML/JSON)");
  } catch (const cv::Exception& e) {
    throw InputError(file.string(), "", std::string("cannot parse: ") + e.err);
  }
  CalibReader r(file, fs);
  SlCalibration c;
  c.file = file;
  try {
    if (r.has("cam_K") || !r.has("cam_int")) {
      c.layout = "scanclean";
      r.intrinsics("cam_K", c.camera);
      c.camera.dist = r.distortion("cam_dist");
      r.intrinsics("proj_K", c.projector);
      c.projector.dist = r.distortion("proj_dist");
      c.R = r.mat3("R");
      c.T = r.vec3("T");
      const auto cs = r.size2("cam_size");
      c.camera.width = cs[0];
      c.camera.height = cs[1];
      const auto ps = r.size2("proj_size");
      c.projector.width = ps[0];
      c.projector.height = ps[1];
      const std::string units = r.string("units");
      if (units.empty()) throw InputError(file.string(), "field 'units'", "missing");
      c.unit_m = unit_to_metres(file, units);
      c.rms = r.scalar("rms", 0.0);
      const double step = r.scalar("graycode_step", 1.0);
      if (step < 1 || step > 64 || step != std::floor(step))
        throw InputError(file.string(), "field 'graycode_step'", "expected an integer 1..64");
      c.graycode_step = static_cast<int>(step);
    } else {
      c.layout = "kamino410";
      r.intrinsics("cam_int", c.camera);
      c.camera.dist = r.distortion("cam_dist");
      r.intrinsics("proj_int", c.projector);
      c.projector.dist = r.distortion("proj_dist");
      c.R = r.mat3("roration");  // sic, the field name in kamino410/procam-calibration
      c.T = r.vec3("translation");
      const auto shape = r.size2("img_shape");  // rows, cols
      c.camera.height = shape[0];
      c.camera.width = shape[1];
      c.unit_m = 0.001;  // chessboard square units, assumed millimetres (not stated)
      c.unit_assumed = true;
      c.rms = r.scalar("rms", 0.0);
    }
  } catch (const cv::Exception& e) {
    throw InputError(file.string(), "", std::string("cannot read: ") + e.err);
  }
  const double orth = (c.R.transpose() * c.R - Eigen::Matrix3d::Identity()).norm();
  if (orth > 1e-4 || c.R.determinant() < 0)
    throw InputError(file.string(), c.layout == "kamino410" ? "field 'roration'" : "field 'R'",
                     "not a rotation matrix (|R^T R - I| = " + std::to_string(orth) + ")");
  return c;
}

void write_sl_calibration(const std::filesystem::path& file, const SlCalibration& c) {
  auto K = [](const Intrinsics& k) -> cv::Mat {
    return (cv::Mat_<double>(3, 3) << k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1);
  };
  auto D = [](const Intrinsics& k) -> cv::Mat {
    return (cv::Mat_<double>(1, 5) << k.dist[0], k.dist[1], k.dist[2], k.dist[3], k.dist[4]);
  };
  cv::Mat R(3, 3, CV_64F), T(3, 1, CV_64F);
  for (int i = 0; i < 3; ++i) {
    T.at<double>(i) = c.T(i);
    for (int j = 0; j < 3; ++j) R.at<double>(i, j) = c.R(i, j);
  }
  const char* unit = nullptr;
  for (const auto& [name, metres] :
       {std::pair{"m", 1.0}, {"cm", 0.01}, {"mm", 0.001}, {"um", 1e-6}})
    if (std::abs(c.unit_m - metres) <= 1e-9 * metres) unit = name;
  if (!unit)
    throw OptionError("write_sl_calibration: unit_m must be 1, 0.01, 0.001 or 1e-6, got " +
                      std::to_string(c.unit_m));
  cv::FileStorage fs(".yml", cv::FileStorage::WRITE | cv::FileStorage::MEMORY);
  fs << "cam_K" << K(c.camera) << "cam_dist" << D(c.camera);
  fs << "proj_K" << K(c.projector) << "proj_dist" << D(c.projector);
  fs << "R" << R << "T" << T;
  fs << "cam_size" << std::vector<int>{c.camera.width, c.camera.height};
  fs << "proj_size" << std::vector<int>{c.projector.width, c.projector.height};
  fs << "units" << std::string(unit) << "rms" << c.rms << "graycode_step" << c.graycode_step;
  const std::string text = fs.releaseAndGetString();
  write_file_atomically(
      file, [&](std::ostream& out) { out << text; }, false);
}

}  // namespace scanclean

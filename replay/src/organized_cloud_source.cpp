#include "scanclean/replay/organized_cloud_source.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>
#include <string>

#include "scanclean/core/errors.h"
#include "scanclean/io/point_cloud_io.h"
#include "scanclean/replay/depth_image_source.h"

namespace scanclean {
namespace fs = std::filesystem;

namespace {

std::string lower_extension(const fs::path& p) {
  std::string e = p.extension().string();
  for (auto& c : e) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return e;
}

bool is_cloud_file(const fs::path& p) {
  const std::string e = lower_extension(p);
  return e == ".pcd" || e == ".ply";
}

//! One axis of the pinhole fit: pixel = f * ratio + c by least squares; rms in pixels.
struct AxisFit {
  double f = 0, c = 0, rms = std::numeric_limits<double>::infinity();
};

AxisFit fit_axis(double n, double sr, double sp, double srr, double srp, double spp) {
  AxisFit a;
  const double det = n * srr - sr * sr;
  if (n < 3 || !(std::abs(det) > 0)) return a;
  a.f = (n * srp - sr * sp) / det;
  a.c = (sp - a.f * sr) / n;
  // sum (p - f r - c)^2 expanded over the accumulated moments.
  const double sse =
      spp + a.f * a.f * srr + n * a.c * a.c - 2 * a.f * srp - 2 * a.c * sp + 2 * a.f * a.c * sr;
  a.rms = std::sqrt(std::max(0.0, sse) / n);
  return a;
}

class OrganizedCloudSource final : public RangeSource {
 public:
  explicit OrganizedCloudSource(std::vector<fs::path> files) : files_(std::move(files)) {}

  void open() override {
    next_ = 0;
    first_ = read(files_.front());
    const Grid& g = first_grid_;
    // Pinhole intrinsics from the first cloud's points.
    double n = 0, sx = 0, su = 0, sxx = 0, sxu = 0, suu = 0;
    double sy = 0, sv = 0, syy = 0, syv = 0, svv = 0;
    for (int v = 0; v < g.rows; ++v)
      for (int u = 0; u < g.cols; ++u) {
        const Eigen::Vector3f& p = first_->points->data[static_cast<std::size_t>(v) * g.cols + u];
        if (!(p.allFinite() && p.z() > 0)) continue;
        const double rx = p.x() / p.z(), ry = p.y() / p.z();
        n += 1;
        sx += rx, su += u, sxx += rx * rx, sxu += rx * u, suu += static_cast<double>(u) * u;
        sy += ry, sv += v, syy += ry * ry, syv += ry * v, svv += static_cast<double>(v) * v;
      }
    const AxisFit fu = fit_axis(n, sx, su, sxx, sxu, suu);
    const AxisFit fv = fit_axis(n, sy, sv, syy, syv, svv);
    if (!(fu.f > 0 && fv.f > 0 && fu.rms < 0.5 && fv.rms < 0.5))
      throw InputError(files_.front().string(), "points",
                       "not a pinhole range image: its points do not project onto their grid "
                       "cells (fit residual " +
                           std::to_string(std::max(fu.rms, fv.rms)) +
                           " px RMS, at most 0.5 expected); filter it as a cloud with "
                           "`scanclean filter`");
    K_.fx = fu.f;
    K_.fy = fv.f;
    K_.cx = fu.c;
    K_.cy = fv.c;
    K_.width = g.cols;
    K_.height = g.rows;
    first_->K = K_;
    fit_rms_px_ = std::max(fu.rms, fv.rms);

    // Timestamps from the names when every one has one and they increase.
    timestamps_us_.clear();
    for (const fs::path& f : files_) {
      const auto t = timestamp_from_name(f.stem().string());
      if (!t || (!timestamps_us_.empty() && *t <= timestamps_us_.back())) {
        timestamps_us_.clear();
        break;
      }
      timestamps_us_.push_back(*t);
    }
    opened_ = true;
  }

  ReadStatus next(RangeFrame& frame, std::chrono::milliseconds) override {
    if (!opened_) throw IoError("organized clouds: next() before open()");
    if (next_ >= files_.size()) return ReadStatus::kEndOfStream;
    RangeFrame f = next_ == 0 && first_ ? std::move(*first_) : *read(files_[next_]);
    first_.reset();
    f.K = K_;
    f.index = next_;
    f.device_ts_us =
        timestamps_us_.empty() ? static_cast<std::int64_t>(next_) * 33'333 : timestamps_us_[next_];
    f.host_ts_ns = f.device_ts_us * 1000;
    ++next_;
    frame = std::move(f);
    return ReadStatus::kOk;
  }

  SourceInfo info() const override {
    SourceInfo s;
    s.uri = files_.size() == 1 ? files_.front().string() : files_.front().parent_path().string();
    s.kind = "organized-clouds";
    char k[160];
    std::snprintf(k, sizeof k,
                  "fx %.2f fy %.2f cx %.2f cy %.2f px, fitted to the points (%.3f px RMS)", K_.fx,
                  K_.fy, K_.cx, K_.cy, fit_rms_px_);
    s.name = std::to_string(files_.size()) + " organized " + std::to_string(first_grid_.cols) +
             "x" + std::to_string(first_grid_.rows) + " cloud" + (files_.size() == 1 ? "" : "s") +
             (has_colour_ ? " with colour" : "") + "; intrinsics " + k;
    s.frame_count = files_.size();
    s.K = K_;
    return s;
  }

 private:
  struct Grid {
    int rows = 0, cols = 0;
  };

  std::optional<RangeFrame> read(const fs::path& file) {
    const PointCloud c = read_point_cloud(file);
    if (c.grid.empty() || c.grid.rows < 2)
      throw InputError(file.string(), "header",
                       "not an organized cloud (expected a PCD with height > 1 or a PLY with a "
                       "range_grid); filter it with `scanclean filter`");
    if (first_grid_.rows == 0) {
      first_grid_ = {c.grid.rows, c.grid.cols};
      has_colour_ = c.has_colors();
    } else if (c.grid.rows != first_grid_.rows || c.grid.cols != first_grid_.cols) {
      throw InputError(file.string(), "header",
                       "organized " + std::to_string(c.grid.cols) + "x" +
                           std::to_string(c.grid.rows) + ", but the sequence's first cloud is " +
                           std::to_string(first_grid_.cols) + "x" +
                           std::to_string(first_grid_.rows));
    }
    RangeFrame f;
    const int W = c.grid.cols, H = c.grid.rows;
    const float nan = std::numeric_limits<float>::quiet_NaN();
    f.points = Image<Eigen::Vector3f>(W, H, Eigen::Vector3f(nan, nan, nan));
    if (has_colour_ && c.has_colors()) f.color = Image<std::array<std::uint8_t, 3>>(W, H);
    for (std::size_t i = 0; i < c.grid.index.size(); ++i) {
      const std::int32_t k = c.grid.index[i];
      if (k < 0) continue;
      const auto idx = static_cast<std::size_t>(k);
      f.points->data[i] = c.positions[idx].cast<float>();
      if (f.color) {
        const auto& rgba = c.colors[idx];
        f.color->data[i] = {rgba[0], rgba[1], rgba[2]};
      }
    }
    return f;
  }

  std::vector<fs::path> files_;
  std::optional<RangeFrame> first_;
  Grid first_grid_;
  bool has_colour_ = false;
  Intrinsics K_;
  double fit_rms_px_ = 0;
  std::vector<std::int64_t> timestamps_us_;
  std::size_t next_ = 0;
  bool opened_ = false;
};

}  // namespace

std::vector<fs::path> list_organized_clouds(const fs::path& path) {
  std::error_code ec;
  if (fs::is_regular_file(path, ec)) {
    if (!is_cloud_file(path))
      throw InputError(path.string(), "", "not a point-cloud file (.pcd or .ply)");
    return {path};
  }
  std::vector<fs::path> out;
  if (fs::is_directory(path, ec))
    for (const auto& e : fs::directory_iterator(path, ec))
      if (e.is_regular_file(ec) && is_cloud_file(e.path())) out.push_back(e.path());
  if (out.empty()) throw InputError(path.string(), "", "no point-cloud files (.pcd or .ply) here");
  std::sort(out.begin(), out.end(), [](const fs::path& a, const fs::path& b) {
    return natural_less(a.filename().string(), b.filename().string());
  });
  return out;
}

std::unique_ptr<RangeSource> make_organized_cloud_source(const fs::path& path) {
  return std::make_unique<OrganizedCloudSource>(list_organized_clouds(path));
}

}  // namespace scanclean

#include "scanclean/preview.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <utility>
#include <vector>

#include "scanclean/core/atomic_file.h"
#include "scanclean/core/errors.h"
#include "scanclean/output_checks.h"
#include "scanclean/run_report.h"
#include "scanclean/summary.h"

namespace scanclean::app {

namespace fs = std::filesystem;

namespace {

const cv::Vec3b kBackground(38, 34, 32);  // BGR, dark
const cv::Vec3b kRemoved(255, 0, 255);    // magenta
constexpr int kBarHeight = 96;
constexpr int kTitleHeight = 30;

// Maps a point to panel pixels and a depth (smaller = nearer).
struct Projector {
  PreviewView view = PreviewView::kAuto;
  Eigen::Matrix3d axes = Eigen::Matrix3d::Identity();  // rows: right, down, forward (kAuto)
  double scale = 1, u0 = 0, v0 = 0;                    // pixel = scale * coordinate + offset
  Eigen::Vector3d forward = Eigen::Vector3d::UnitZ();  // viewing direction (world)

  bool project(const Eigen::Vector3d& p, double& u, double& v, double& depth) const {
    if (view == PreviewView::kCamera) {
      if (!(p.z() > 1e-6)) return false;
      u = scale * p.x() / p.z() + u0;
      v = scale * p.y() / p.z() + v0;
      depth = p.z();
      return true;
    }
    const Eigen::Vector3d q = axes * p;
    u = scale * q.x() + u0;
    v = scale * q.y() + v0;
    depth = q.z();
    return true;
  }
  // The direction from a point towards the viewer.
  Eigen::Vector3d to_viewer(const Eigen::Vector3d& p) const {
    if (view == PreviewView::kCamera) return -p.normalized();
    return -forward;
  }
};

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  const auto k = static_cast<std::size_t>(q * static_cast<double>(v.size() - 1));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

// Chooses the view so that the 1st-99th percentile box of the points fills the panel.
Projector make_projector(const PointCloud& before, const PointCloud& after,
                         const PreviewOptions& o) {
  Projector pr;
  pr.view = o.view;
  const PointCloud& ref = before.empty() ? after : before;
  const std::size_t n = ref.size();
  const std::size_t step = std::max<std::size_t>(1, n / 200000);
  if (o.view == PreviewView::kAuto) {
    Eigen::AlignedBox3d box = bounding_box(ref);
    const Eigen::Vector3d ext = box.sizes();
    int depth_axis = 0;
    for (int k = 1; k < 3; ++k)
      if (ext[k] < ext[depth_axis]) depth_axis = k;
    // "Up" is y when y is not the depth axis (the usual convention), else z.
    const int up_axis = depth_axis != 1 ? 1 : 2;
    const int right_axis = 3 - depth_axis - up_axis;
    Eigen::Vector3d forward = -Eigen::Vector3d::Unit(depth_axis);  // viewer on the + side
    // Look from the side most output normals face.
    if (after.has_normals()) {
      std::size_t facing = 0;
      for (const auto& nrm : after.normals)
        if (nrm.cast<double>().dot(forward) < 0) ++facing;
      if (facing * 2 < after.normals.size()) forward = -forward;
    }
    const Eigen::Vector3d down = -Eigen::Vector3d::Unit(up_axis);
    Eigen::Vector3d right = down.cross(forward);  // right-handed: right x down = forward
    (void)right_axis;
    pr.axes.row(0) = right.transpose();
    pr.axes.row(1) = down.transpose();
    pr.axes.row(2) = forward.transpose();
    pr.forward = forward;
  }
  std::vector<double> us, vs;
  for (std::size_t i = 0; i < n; i += step) {
    double u, v, d;
    Projector unit = pr;
    unit.scale = 1;
    unit.u0 = unit.v0 = 0;
    if (unit.project(ref.positions[i], u, v, d)) {
      us.push_back(u);
      vs.push_back(v);
    }
  }
  if (us.empty()) return pr;
  const double ulo = percentile(us, 0.01), uhi = percentile(us, 0.99);
  const double vlo = percentile(vs, 0.01), vhi = percentile(vs, 0.99);
  const double margin = 0.06;
  const double w = o.panel_width * (1 - 2 * margin), h = o.panel_height * (1 - 2 * margin);
  pr.scale = std::min(w / std::max(uhi - ulo, 1e-12), h / std::max(vhi - vlo, 1e-12));
  pr.u0 = o.panel_width / 2.0 - pr.scale * (ulo + uhi) / 2;
  pr.v0 = o.panel_height / 2.0 - pr.scale * (vlo + vhi) / 2;
  return pr;
}

// Splat half-size from the points per pixel of the area they cover (occupied 4 x 4 cells).
int splat_radius(const Projector& pr, const PointCloud& c, const PreviewOptions& o) {
  const int cw = (o.panel_width + 3) / 4, ch = (o.panel_height + 3) / 4;
  std::vector<std::uint8_t> cell(static_cast<std::size_t>(cw) * ch, 0);
  std::size_t inside = 0, cells = 0;
  for (const auto& p : c.positions) {
    double u, v, d;
    if (!pr.project(p, u, v, d) || !(u >= 0 && v >= 0 && u < o.panel_width && v < o.panel_height))
      continue;
    ++inside;
    auto& k = cell[static_cast<std::size_t>(v / 4) * cw + static_cast<std::size_t>(u / 4)];
    cells += k == 0;
    k = 1;
  }
  if (inside == 0) return 1;
  const double px_per_point = 16.0 * static_cast<double>(cells) / static_cast<double>(inside);
  return std::clamp(static_cast<int>(std::ceil(0.75 * std::sqrt(px_per_point))), 1, 5);
}

class Canvas {
 public:
  Canvas(int w, int h)
      : img_(h, w, CV_8UC3, cv::Scalar(kBackground[0], kBackground[1], kBackground[2])),
        z_(h, w, CV_32F, cv::Scalar(std::numeric_limits<float>::max())) {}
  void splat(double u, double v, double depth, int r, const cv::Vec3b& c, bool depth_test) {
    const int cu = static_cast<int>(std::lround(u)), cv_ = static_cast<int>(std::lround(v));
    for (int y = cv_ - r; y <= cv_ + r; ++y) {
      if (y < 0 || y >= img_.rows) continue;
      for (int x = cu - r; x <= cu + r; ++x) {
        if (x < 0 || x >= img_.cols) continue;
        float& z = z_.at<float>(y, x);
        if (depth_test && !(depth < z)) continue;
        if (depth_test) z = static_cast<float>(depth);
        img_.at<cv::Vec3b>(y, x) = c;
      }
    }
  }
  cv::Mat& image() { return img_; }

  //! Shades the drawn pixels by the surface the depth buffer holds (normal from the depth
  //! gradient; `pixel_m(depth)` = the width of a pixel in metres at that depth), so that the
  //! shape and the noise show the same way in both panels.
  template <typename PixelSize>
  void shade_by_depth(PixelSize pixel_m, int splat_radius) {
    const float far = std::numeric_limits<float>::max();
    // The depth smoothed over about a splat (neighbours on the same surface only: within a few
    // pixel widths in depth), so that the flat squares' edges do not read as steps.
    cv::Mat z = z_.clone();
    const int k = splat_radius;
    for (int y = 0; y < img_.rows; ++y)
      for (int x = 0; x < img_.cols; ++x) {
        const float zc = z_.at<float>(y, x);
        if (zc == far) continue;
        const double tol = 3.0 * (2 * k + 1) * pixel_m(zc);
        double sum = 0;
        int n = 0;
        for (int dy = -k; dy <= k; ++dy)
          for (int dx = -k; dx <= k; ++dx) {
            const int yy = y + dy, xx = x + dx;
            if (yy < 0 || xx < 0 || yy >= img_.rows || xx >= img_.cols) continue;
            const float zn = z_.at<float>(yy, xx);
            if (zn == far || std::abs(zn - zc) > tol) continue;
            sum += zn;
            ++n;
          }
        z.at<float>(y, x) = static_cast<float>(sum / n);
      }
    for (int y = 1; y + 1 < img_.rows; ++y)
      for (int x = 1; x + 1 < img_.cols; ++x) {
        const float zc = z.at<float>(y, x);
        if (zc == far) continue;
        auto dz = [&](int dx, int dy) {
          const float a = z.at<float>(y - dy, x - dx), b = z.at<float>(y + dy, x + dx);
          if (a != far && b != far) return (b - a) / 2.0;
          if (b != far) return double(b - zc);
          if (a != far) return double(zc - a);
          return 0.0;
        };
        const double px = pixel_m(zc);
        Eigen::Vector3d n(-dz(1, 0) / px, -dz(0, 1) / px, 1.0);
        const double lit =
            std::clamp(n.normalized().dot(Eigen::Vector3d(-0.3, -0.4, 0.866)), 0.0, 1.0);
        const double s = 0.3 + 0.7 * lit;
        cv::Vec3b& c = img_.at<cv::Vec3b>(y, x);
        c = cv::Vec3b(cv::saturate_cast<uchar>(c[0] * s), cv::saturate_cast<uchar>(c[1] * s),
                      cv::saturate_cast<uchar>(c[2] * s));
      }
  }

 private:
  cv::Mat img_;
  cv::Mat z_;
};

// Diverging map (BGR): t in [-1, 1], blue - light grey - red.
cv::Vec3b diverging(double t) {
  t = std::clamp(t, -1.0, 1.0);
  const std::array<double, 3> mid{221, 221, 221}, neg{192, 76, 59}, pos{38, 4, 180};
  const auto& end = t < 0 ? neg : pos;
  const double a = std::abs(t);
  return cv::Vec3b(static_cast<uchar>(mid[0] + a * (end[0] - mid[0])),
                   static_cast<uchar>(mid[1] + a * (end[1] - mid[1])),
                   static_cast<uchar>(mid[2] + a * (end[2] - mid[2])));
}

void text(cv::Mat& img, const std::string& s, int x, int y, double size = 0.5) {
  cv::putText(img, s, cv::Point(x, y), cv::FONT_HERSHEY_SIMPLEX, size, cv::Scalar(235, 235, 235), 1,
              cv::LINE_AA);
}

std::string mm(double metres) {
  char b[32];
  std::snprintf(b, sizeof b, "%.3g mm", metres * 1e3);
  return b;
}

std::string lower(std::string s) {
  for (auto& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// The two panels from one viewpoint: the input in grey with the removed points on top, and
// the output coloured by displacement; both shaded by their depth buffers.
std::pair<cv::Mat, cv::Mat> render_pair(const Projector& pr, const PointCloud& before,
                                        const PointCloud& after, const PointCloud& removed,
                                        const Attribute* disp, double range_m,
                                        const PreviewOptions& o) {
  const int W = o.panel_width, H = o.panel_height;
  // Left: the input, grey, and the removed points on top.
  Canvas left(W, H);
  const int r_before = splat_radius(pr, before, o);
  for (std::size_t i = 0; i < before.size(); ++i) {
    double u, v, d;
    if (!pr.project(before.positions[i], u, v, d)) continue;
    left.splat(u, v, d, r_before, cv::Vec3b(200, 200, 200), true);
  }
  auto pixel_m = [&pr](float depth) {
    return pr.view == PreviewView::kCamera ? depth / pr.scale : 1.0 / pr.scale;
  };
  left.shade_by_depth(pixel_m, r_before);
  // Removed points drawn a size smaller when they are many (more than 2 % of the input), so
  // that they mark the surface instead of hiding it.
  const int r_removed =
      removed.size() * 50 > before.size() ? std::max(0, r_before - 1) : std::max(1, r_before);
  for (const auto& p : removed.positions) {
    double u, v, d;
    if (pr.project(p, u, v, d)) left.splat(u, v, d, r_removed, kRemoved, false);
  }
  // Right: the output coloured by displacement.
  Canvas right(W, H);
  const int r_after = splat_radius(pr, after, o);
  for (std::size_t i = 0; i < after.size(); ++i) {
    double u, v, d;
    if (!pr.project(after.positions[i], u, v, d)) continue;
    const double t = disp ? disp->values[i] / range_m : 0.0;
    right.splat(u, v, d, r_after, diverging(t), true);
  }
  right.shade_by_depth(pixel_m, r_after);

  return {left.image(), right.image()};
}

}  // namespace

std::shared_ptr<std::string> add_preview_option(CLI::App& cmd) {
  auto path = std::make_shared<std::string>();
  cmd.add_option("--preview", *path,
                 "Write a PNG of what the filter did: its input (removed points in magenta) and "
                 "its output coloured by how far each point moved along its normal (mm), side "
                 "by side from the same viewpoint")
      ->type_name("FILE.png");
  return path;
}

void check_preview_path(const std::string& command, const std::string& path) {
  if (path.empty()) return;
  const fs::path p(path);
  const std::string who = command + ": --preview \"" + path + "\"";
  if (lower(p.extension().string()) != ".png") throw OptionError(who + ": must end in .png");
  // The folder exists and is writable, the path is no folder (output_checks.h; it also notes
  // the path for --report).
  check_output_files(command, {}, {{"--preview", p}}, false);
}

PreviewFacts write_preview(const fs::path& png, const PointCloud& before, const PointCloud& after,
                           const PointCloud& removed, const PreviewOptions& o) {
  PreviewFacts facts;
  facts.before = before.size();
  facts.after = after.size();
  facts.removed = removed.size();
  const Projector pr = make_projector(before, after, o);
  const int W = o.panel_width, H = o.panel_height;

  // Colour range: the 98th percentile of |displacement|.
  const Attribute* disp = after.find_attribute("displacement");
  std::vector<double> mag;
  if (disp) {
    mag.reserve(disp->values.size());
    for (double d : disp->values) mag.push_back(std::abs(d));
  }
  facts.range_m = std::max(percentile(mag, 0.98), 1e-9);
  facts.median_abs_m = percentile(mag, 0.5);

  const auto [left, right] = render_pair(pr, before, after, removed, disp, facts.range_m, o);
  // The detail: the panels' central third, magnified 3x (the same renderer, zoomed).
  constexpr int kZoom = 3;
  Projector zoomed = pr;
  zoomed.scale = pr.scale * kZoom;
  zoomed.u0 = kZoom * pr.u0 - (kZoom - 1) * W / 2.0;
  zoomed.v0 = kZoom * pr.v0 - (kZoom - 1) * H / 2.0;
  const auto [left_zoom, right_zoom] =
      render_pair(zoomed, before, after, removed, disp, facts.range_m, o);

  const int row2 = kTitleHeight + H + kTitleHeight;  // top of the detail panels
  cv::Mat out(row2 + H + kBarHeight, 2 * W + 6, CV_8UC3, cv::Scalar(20, 20, 20));
  left.copyTo(out(cv::Rect(0, kTitleHeight, W, H)));
  right.copyTo(out(cv::Rect(W + 6, kTitleHeight, W, H)));
  left_zoom.copyTo(out(cv::Rect(0, row2, W, H)));
  right_zoom.copyTo(out(cv::Rect(W + 6, row2, W, H)));
  const cv::Rect detail(W / 2 - W / (2 * kZoom), kTitleHeight + H / 2 - H / (2 * kZoom), W / kZoom,
                        H / kZoom);
  for (int x0 : {0, W + 6})
    cv::rectangle(out, detail + cv::Point(x0, 0), cv::Scalar(0, 215, 255), 1);
  text(out,
       "before: " + with_thousands(facts.before) + " points, " + with_thousands(facts.removed) +
           " removed (magenta)",
       8, 20);
  text(out,
       "after: " + with_thousands(facts.after) +
           " points, coloured by displacement along the normal",
       W + 14, 20);
  text(out, "detail: the framed centre, magnified 3x", 8, kTitleHeight + H + 20);
  // Colour bar with its units.
  const int bx = W + 6 + 40, bw = W - 80, by = row2 + H + 12, bh = 16;
  for (int x = 0; x < bw; ++x) {
    const double t = 2.0 * x / (bw - 1) - 1.0;
    cv::line(out, cv::Point(bx + x, by), cv::Point(bx + x, by + bh), cv::Scalar(diverging(t)));
  }
  const std::string lo = "-" + mm(facts.range_m), hi = "+" + mm(facts.range_m);
  text(out, lo, bx - 20, by + bh + 18, 0.45);
  text(out, "0", bx + bw / 2 - 4, by + bh + 18, 0.45);
  text(out, hi, bx + bw - 50, by + bh + 18, 0.45);
  text(out, "displacement along the normal (" + mm(facts.median_abs_m) + " median |d|)",
       bx + bw / 2 - 170, by + bh + 38, 0.45);
  text(out, "view: " + std::string(o.view == PreviewView::kCamera ? "camera" : "orthographic"), 8,
       by + bh + 18, 0.45);
  if (!o.title.empty()) text(out, o.title, 8, out.rows - 8, 0.42);

  std::vector<uchar> bytes;
  if (!cv::imencode(".png", out, bytes, {cv::IMWRITE_PNG_COMPRESSION, 9}))
    throw IoError(png.string() + ": cannot encode PNG");
  write_file_atomically(png, [&](std::ostream& os) {
    os.write(reinterpret_cast<const char*>(bytes.data()),
             static_cast<std::streamsize>(bytes.size()));
  });
  return facts;
}

std::string preview_summary_text(const std::string& path, const PreviewFacts& f) {
  return path + " (colour range +-" + mm(f.range_m) + ", median |displacement| " +
         mm(f.median_abs_m) + ")";
}

}  // namespace scanclean::app

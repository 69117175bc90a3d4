#include "mesh_render.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "scanclean/core/atomic_file.h"
#include "scanclean/core/errors.h"

namespace scanclean::bench {
namespace {

// Rasterises one mesh into a panel: orthographic projection, z-buffer (larger camera z is
// nearer), flat Lambert shading from the face normal (two-sided, so inconsistent orientation
// shows no black faces), plus a little ambient light.
void draw_panel(const TriangleMesh& mesh, const RenderView& view, const Eigen::Vector3d& centre,
                double scale, cv::Mat& image) {
  const int size = image.rows;
  std::vector<float> depth(static_cast<std::size_t>(size) * size,
                           -std::numeric_limits<float>::infinity());
  std::vector<Eigen::Vector3d> cam(mesh.vertices.size());
  for (std::size_t i = 0; i < cam.size(); ++i) {
    const Eigen::Vector3d q = view.rotation * (mesh.vertices[i] - centre);
    // Pixel coordinates: x right, y down.
    cam[i] = Eigen::Vector3d(0.5 * size + q.x() * scale, 0.5 * size - q.y() * scale, q.z());
  }
  const Eigen::Vector3d light = view.light.normalized();
  for (const auto& t : mesh.triangles) {
    const Eigen::Vector3d& a = cam[static_cast<std::size_t>(t[0])];
    const Eigen::Vector3d& b = cam[static_cast<std::size_t>(t[1])];
    const Eigen::Vector3d& c = cam[static_cast<std::size_t>(t[2])];
    // Shading from the camera-frame normal (screen y is flipped, so undo it for the normal).
    const Eigen::Vector3d pa(a.x(), -a.y(), a.z() * scale), pb(b.x(), -b.y(), b.z() * scale),
        pc(c.x(), -c.y(), c.z() * scale);
    Eigen::Vector3d n = (pb - pa).cross(pc - pa);
    const double len = n.norm();
    if (!(len > 0)) continue;
    n /= len;
    const double lambert = std::abs(n.dot(light));
    const double shade = 0.15 + 0.85 * lambert;
    const cv::Vec3b colour(static_cast<uchar>(std::min(255.0, 235 * shade)),
                           static_cast<uchar>(std::min(255.0, 225 * shade)),
                           static_cast<uchar>(std::min(255.0, 210 * shade)));
    const double area = (b.x() - a.x()) * (c.y() - a.y()) - (b.y() - a.y()) * (c.x() - a.x());
    if (std::abs(area) < 1e-12) continue;
    const int x0 = std::max(0, static_cast<int>(std::floor(std::min({a.x(), b.x(), c.x()}))));
    const int x1 = std::min(size - 1, static_cast<int>(std::ceil(std::max({a.x(), b.x(), c.x()}))));
    const int y0 = std::max(0, static_cast<int>(std::floor(std::min({a.y(), b.y(), c.y()}))));
    const int y1 = std::min(size - 1, static_cast<int>(std::ceil(std::max({a.y(), b.y(), c.y()}))));
    for (int y = y0; y <= y1; ++y) {
      for (int x = x0; x <= x1; ++x) {
        const double px = x + 0.5, py = y + 0.5;
        const double w0 = ((b.x() - px) * (c.y() - py) - (b.y() - py) * (c.x() - px)) / area;
        const double w1 = ((c.x() - px) * (a.y() - py) - (c.y() - py) * (a.x() - px)) / area;
        const double w2 = 1.0 - w0 - w1;
        if (w0 < 0 || w1 < 0 || w2 < 0) continue;
        const float z = static_cast<float>(w0 * a.z() + w1 * b.z() + w2 * c.z());
        float& d = depth[static_cast<std::size_t>(y) * size + x];
        if (z <= d) continue;
        d = z;
        image.at<cv::Vec3b>(y, x) = colour;
      }
    }
  }
}

}  // namespace

void render_meshes_png(const std::vector<RenderPanel>& panels, const RenderView& view,
                       const std::filesystem::path& png) {
  if (panels.empty()) return;
  const std::size_t frame = std::min(view.frame_panel, panels.size() - 1);
  if (!panels[frame].mesh) return;
  const int size = view.panel_size;
  Eigen::AlignedBox3d box;
  for (const auto& v : panels[frame].mesh->vertices) box.extend(view.rotation * v);
  const Eigen::Vector3d centre = view.rotation.transpose() * box.center();
  const Eigen::Vector3d extent = box.sizes();
  const double scale = 0.9 * size / std::max({extent.x(), extent.y(), 1e-12});
  cv::Mat all(size + 40, size * static_cast<int>(panels.size()), CV_8UC3, cv::Scalar(40, 40, 40));
  for (std::size_t i = 0; i < panels.size(); ++i) {
    cv::Mat panel = all(cv::Rect(static_cast<int>(i) * size, 40, size, size));
    if (panels[i].mesh) draw_panel(*panels[i].mesh, view, centre, scale, panel);
    cv::putText(all, panels[i].title, cv::Point(static_cast<int>(i) * size + 10, 28),
                cv::FONT_HERSHEY_SIMPLEX, 0.6, cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  }
  std::vector<uchar> bytes;
  if (!cv::imencode(".png", all, bytes)) throw IoError(png.string() + ": PNG encoding failed");
  write_file_atomically(png, [&](std::ostream& os) {
    os.write(reinterpret_cast<const char*>(bytes.data()),
             static_cast<std::streamsize>(bytes.size()));
  });
}

}  // namespace scanclean::bench

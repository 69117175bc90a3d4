// The mesh ground truth (needs io's read_triangle_mesh and eval's MeshDistance).
#include <algorithm>
#include <cmath>

#include "protocol.h"
#include "scanclean/core/errors.h"
#include "shapes.h"

#ifdef SCANCLEAN_BENCH_HAVE_MESH
#include "scanclean/core/triangle_mesh.h"
#include "scanclean/eval/mesh_distance.h"
#include "scanclean/io/triangle_mesh_io.h"
#endif

namespace scanclean::bench {

#ifdef SCANCLEAN_BENCH_HAVE_MESH

namespace {

class MeshShape final : public Shape {
 public:
  MeshShape(TriangleMesh mesh, std::string name) : mesh_(std::move(mesh)), name_(std::move(name)) {
    normalise_unit_sphere(mesh_.vertices);
    for (const auto& v : mesh_.vertices) box_.extend(v);
    cumulative_.reserve(mesh_.triangles.size());
    double total = 0;
    for (const auto& t : mesh_.triangles) {
      const Eigen::Vector3d& a = mesh_.vertices[t[0]];
      total += 0.5 * (mesh_.vertices[t[1]] - a).cross(mesh_.vertices[t[2]] - a).norm();
      cumulative_.push_back(total);
    }
    area_ = total;
    distance_ = std::make_unique<MeshDistance>(mesh_);
  }
  std::string name() const override { return name_; }
  std::vector<Eigen::Vector3d> sample(std::size_t n, Rng& rng) const override {
    std::vector<Eigen::Vector3d> out(n);
    for (auto& p : out) {
      const double pick = rng.uniform() * area_;
      auto it = std::upper_bound(cumulative_.begin(), cumulative_.end(), pick);
      if (it == cumulative_.end()) --it;
      const auto& t = mesh_.triangles[static_cast<std::size_t>(it - cumulative_.begin())];
      const double r1 = std::sqrt(rng.uniform()), r2 = rng.uniform();
      p = (1 - r1) * mesh_.vertices[t[0]] + r1 * (1 - r2) * mesh_.vertices[t[1]] +
          r1 * r2 * mesh_.vertices[t[2]];
    }
    return out;
  }
  double distance(const Eigen::Vector3d& p) const override { return distance_->distance(p); }
  Eigen::AlignedBox3d box() const override { return box_; }
  double area() const override { return area_; }

 private:
  TriangleMesh mesh_;
  std::string name_;
  Eigen::AlignedBox3d box_;
  std::vector<double> cumulative_;
  double area_ = 0;
  std::unique_ptr<MeshDistance> distance_;
};

}  // namespace

std::unique_ptr<Shape> make_mesh_shape(const std::filesystem::path& ply, const std::string& name) {
  return std::make_unique<MeshShape>(read_triangle_mesh(ply), name);
}

#else

std::unique_ptr<Shape> make_mesh_shape(const std::filesystem::path& ply, const std::string&) {
  throw UnavailableError(ply.string() +
                         ": scanclean_bench was built without the io/eval modules (mesh reading "
                         "and exact mesh distance)");
}

#endif

}  // namespace scanclean::bench

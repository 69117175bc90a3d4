#include "shapes.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <utility>

namespace scanclean::bench {

namespace {

Eigen::Vector3d random_unit(Rng& rng) {
  Eigen::Vector3d v;
  do {
    v = Eigen::Vector3d(rng.normal(), rng.normal(), rng.normal());
  } while (v.squaredNorm() < 1e-20);
  return v.normalized();
}

class Sphere final : public Shape {
 public:
  std::string name() const override { return "sphere"; }
  std::vector<Eigen::Vector3d> sample(std::size_t n, Rng& rng) const override {
    std::vector<Eigen::Vector3d> out(n);
    for (auto& p : out) p = random_unit(rng);
    return out;
  }
  double distance(const Eigen::Vector3d& p) const override { return std::abs(p.norm() - 1.0); }
  Eigen::AlignedBox3d box() const override {
    return {Eigen::Vector3d::Constant(-1), Eigen::Vector3d::Constant(1)};
  }
  double area() const override { return 4 * M_PI; }
};

class Torus final : public Shape {
 public:
  std::string name() const override { return "torus"; }
  std::vector<Eigen::Vector3d> sample(std::size_t n, Rng& rng) const override {
    std::vector<Eigen::Vector3d> out;
    out.reserve(n);
    while (out.size() < n) {
      const double u = rng.uniform(0, 2 * M_PI);
      const double v = rng.uniform(0, 2 * M_PI);
      // Area element is proportional to (R + r cos v): accept with that probability.
      if (rng.uniform() * (kR + kr) > kR + kr * std::cos(v)) continue;
      const double ring = kR + kr * std::cos(v);
      out.emplace_back(ring * std::cos(u), ring * std::sin(u), kr * std::sin(v));
    }
    return out;
  }
  double distance(const Eigen::Vector3d& p) const override {
    const double q = std::hypot(p.x(), p.y()) - kR;
    return std::abs(std::hypot(q, p.z()) - kr);
  }
  Eigen::AlignedBox3d box() const override {
    return {Eigen::Vector3d(-1, -1, -kr), Eigen::Vector3d(1, 1, kr)};
  }
  double area() const override { return 4 * M_PI * M_PI * kR * kr; }

 private:
  static constexpr double kR = 0.7;
  static constexpr double kr = 0.3;
};

class RoundedBox final : public Shape {
 public:
  RoundedBox() {
    b_ = Eigen::Vector3d(0.5, 0.35, 0.2);
    rho_ = 0.15;
    const double s = 1.0 / (b_.norm() + rho_);
    b_ *= s;
    rho_ *= s;
    // Component areas: 3 face pairs, 3 edge groups (4 quarter cylinders each), 8 corner octants.
    const Eigen::Vector3d& b = b_;
    areas_ = {8 * b.y() * b.z(),       8 * b.x() * b.z(),       8 * b.x() * b.y(),
              4 * M_PI * rho_ * b.x(), 4 * M_PI * rho_ * b.y(), 4 * M_PI * rho_ * b.z(),
              4 * M_PI * rho_ * rho_};
    total_ = 0;
    for (double a : areas_) total_ += a;
  }
  std::string name() const override { return "rounded_box"; }
  std::vector<Eigen::Vector3d> sample(std::size_t n, Rng& rng) const override {
    std::vector<Eigen::Vector3d> out;
    out.reserve(n);
    while (out.size() < n) {
      double pick = rng.uniform() * total_;
      int c = 0;
      while (c < 6 && pick >= areas_[c]) pick -= areas_[c++];
      auto sgn = [&rng]() { return rng.uniform() < 0.5 ? -1.0 : 1.0; };
      Eigen::Vector3d p;
      if (c < 3) {  // flat face normal to axis c
        const int a1 = (c + 1) % 3, a2 = (c + 2) % 3;
        p[c] = sgn() * (b_[c] + rho_);
        p[a1] = rng.uniform(-b_[a1], b_[a1]);
        p[a2] = rng.uniform(-b_[a2], b_[a2]);
      } else if (c < 6) {  // quarter cylinders along axis c - 3
        const int ax = c - 3, a1 = (ax + 1) % 3, a2 = (ax + 2) % 3;
        const double t = rng.uniform(0, 0.5 * M_PI);
        p[ax] = rng.uniform(-b_[ax], b_[ax]);
        p[a1] = sgn() * (b_[a1] + rho_ * std::cos(t));
        p[a2] = sgn() * (b_[a2] + rho_ * std::sin(t));
      } else {  // corner octants: a uniform direction picks its own octant
        const Eigen::Vector3d d = random_unit(rng);
        for (int i = 0; i < 3; ++i) p[i] = (d[i] < 0 ? -b_[i] : b_[i]) + rho_ * d[i];
      }
      out.push_back(p);
    }
    return out;
  }
  double distance(const Eigen::Vector3d& p) const override {
    const Eigen::Vector3d q = p.cwiseAbs() - b_;
    const double sdf = q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0) - rho_;
    return std::abs(sdf);
  }
  Eigen::AlignedBox3d box() const override {
    const Eigen::Vector3d e = b_ + Eigen::Vector3d::Constant(rho_);
    return {-e, e};
  }
  double area() const override { return total_; }

 private:
  Eigen::Vector3d b_;
  double rho_;
  std::array<double, 7> areas_{};
  double total_;
};

// A closed polyhedron given by convex planar faces (vertex loops), normalised to the unit sphere
// (vertices' bounding-box centre to the origin, farthest vertex at radius 1). Every polygon edge
// is a crease. Distances are exact: the minimum over faces of the point-to-polygon distance.
class Polyhedron final : public Shape {
 public:
  Polyhedron(std::string name, std::vector<std::vector<Eigen::Vector3d>> faces)
      : name_(std::move(name)), faces_(std::move(faces)) {
    Eigen::AlignedBox3d b;
    for (const auto& f : faces_)
      for (const auto& v : f) b.extend(v);
    const Eigen::Vector3d c = b.center();
    double r = 0;
    for (const auto& f : faces_)
      for (const auto& v : f) r = std::max(r, (v - c).norm());
    for (auto& f : faces_)
      for (auto& v : f) v = (v - c) / r;
    for (const auto& f : faces_) {
      Face face;
      face.v = f;
      Eigen::Vector3d n = Eigen::Vector3d::Zero();
      for (std::size_t k = 1; k + 1 < f.size(); ++k) {
        const Eigen::Vector3d cr = (f[k] - f[0]).cross(f[k + 1] - f[0]);
        n += cr;
        face.tri_area.push_back(0.5 * cr.norm());
        face.area += face.tri_area.back();
      }
      face.n = n.normalized();
      total_ += face.area;
      faces_data_.push_back(std::move(face));
      for (std::size_t k = 0; k < f.size(); ++k) box_.extend(f[k]);
    }
    // Creases: every polygon edge once (shared edges appear twice; duplicates are harmless).
    for (const auto& f : faces_data_)
      for (std::size_t k = 0; k < f.v.size(); ++k)
        creases_.push_back({f.v[k], f.v[(k + 1) % f.v.size()]});
  }
  std::string name() const override { return name_; }
  std::vector<Eigen::Vector3d> sample(std::size_t n, Rng& rng) const override {
    std::vector<Eigen::Vector3d> out;
    out.reserve(n);
    while (out.size() < n) {
      double pick = rng.uniform() * total_;
      std::size_t fi = 0;
      while (fi + 1 < faces_data_.size() && pick >= faces_data_[fi].area)
        pick -= faces_data_[fi++].area;
      const Face& f = faces_data_[fi];
      std::size_t t = 0;
      while (t + 1 < f.tri_area.size() && pick >= f.tri_area[t]) pick -= f.tri_area[t++];
      double u = rng.uniform(), v = rng.uniform();
      if (u + v > 1) {
        u = 1 - u;
        v = 1 - v;
      }
      out.push_back(f.v[0] + u * (f.v[t + 1] - f.v[0]) + v * (f.v[t + 2] - f.v[0]));
    }
    return out;
  }
  double distance(const Eigen::Vector3d& p) const override {
    Eigen::Vector3d foot;
    return nearest(p, foot);
  }
  Eigen::AlignedBox3d box() const override { return box_; }
  double area() const override { return total_; }
  bool has_creases() const override { return true; }
  double crease_distance(const Eigen::Vector3d& p) const override {
    Eigen::Vector3d foot;
    nearest(p, foot);
    double best = std::numeric_limits<double>::infinity();
    for (const auto& [a, b] : creases_) best = std::min(best, segment_distance(foot, a, b));
    return best;
  }

 private:
  struct Face {
    std::vector<Eigen::Vector3d> v;
    Eigen::Vector3d n;
    std::vector<double> tri_area;
    double area = 0;
  };
  static double segment_distance(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                 const Eigen::Vector3d& b) {
    const Eigen::Vector3d ab = b - a;
    const double t = std::clamp((p - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0);
    return (p - (a + t * ab)).norm();
  }
  // Distance from p to the surface and the nearest surface point.
  double nearest(const Eigen::Vector3d& p, Eigen::Vector3d& foot) const {
    double best = std::numeric_limits<double>::infinity();
    for (const Face& f : faces_data_) {
      const double z = (p - f.v[0]).dot(f.n);
      const Eigen::Vector3d q = p - z * f.n;
      bool inside = true;
      for (std::size_t k = 0; k < f.v.size() && inside; ++k) {
        const Eigen::Vector3d& a = f.v[k];
        const Eigen::Vector3d& b = f.v[(k + 1) % f.v.size()];
        inside = (b - a).cross(q - a).dot(f.n) >= 0;
      }
      if (inside) {
        if (std::abs(z) < best) {
          best = std::abs(z);
          foot = q;
        }
        continue;
      }
      for (std::size_t k = 0; k < f.v.size(); ++k) {
        const Eigen::Vector3d& a = f.v[k];
        const Eigen::Vector3d ab = f.v[(k + 1) % f.v.size()] - a;
        const double t = std::clamp((p - a).dot(ab) / ab.squaredNorm(), 0.0, 1.0);
        const Eigen::Vector3d c = a + t * ab;
        const double d = (p - c).norm();
        if (d < best) {
          best = d;
          foot = c;
        }
      }
    }
    return best;
  }

  std::string name_;
  std::vector<std::vector<Eigen::Vector3d>> faces_;
  std::vector<Face> faces_data_;
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> creases_;
  Eigen::AlignedBox3d box_;
  double total_ = 0;
};

// A prism: the convex polygon `section` (counter-clockwise in the xz plane) extruded over
// y in [-depth, depth].
std::vector<std::vector<Eigen::Vector3d>> prism(const std::vector<Eigen::Vector2d>& section,
                                                double depth) {
  std::vector<std::vector<Eigen::Vector3d>> faces;
  auto at = [&](std::size_t k, double y) {
    return Eigen::Vector3d(section[k].x(), y, section[k].y());
  };
  const std::size_t m = section.size();
  std::vector<Eigen::Vector3d> front, back;
  for (std::size_t k = 0; k < m; ++k) {
    front.push_back(at(k, -depth));
    back.push_back(at(m - 1 - k, depth));
  }
  faces.push_back(front);
  faces.push_back(back);
  for (std::size_t k = 0; k < m; ++k) {
    const std::size_t l = (k + 1) % m;
    faces.push_back({at(k, -depth), at(k, depth), at(l, depth), at(l, -depth)});
  }
  return faces;
}

// Disjoint surfaces: the distance is the minimum of the parts' (exact), sampling by area.
class Composite final : public Shape {
 public:
  struct Part {
    std::unique_ptr<Shape> shape;
    Eigen::Vector3d centre;
    double scale;
  };
  Composite(std::string name, std::vector<Part> parts, double normalise)
      : name_(std::move(name)), parts_(std::move(parts)) {
    for (auto& p : parts_) {
      p.centre *= normalise;
      p.scale *= normalise;
      const Eigen::AlignedBox3d b = p.shape->box();
      box_.extend(p.centre + p.scale * b.min());
      box_.extend(p.centre + p.scale * b.max());
      areas_.push_back(p.scale * p.scale * p.shape->area());
      total_ += areas_.back();
    }
  }
  std::string name() const override { return name_; }
  std::vector<Eigen::Vector3d> sample(std::size_t n, Rng& rng) const override {
    std::vector<Eigen::Vector3d> out;
    out.reserve(n);
    while (out.size() < n) {
      double pick = rng.uniform() * total_;
      std::size_t k = 0;
      while (k + 1 < parts_.size() && pick >= areas_[k]) pick -= areas_[k++];
      const Part& p = parts_[k];
      out.push_back(p.centre + p.scale * p.shape->sample(1, rng).front());
    }
    return out;
  }
  double distance(const Eigen::Vector3d& x) const override {
    double best = std::numeric_limits<double>::infinity();
    for (const Part& p : parts_)
      best = std::min(best, p.scale * p.shape->distance((x - p.centre) / p.scale));
    return best;
  }
  Eigen::AlignedBox3d box() const override { return box_; }
  double area() const override { return total_; }

 private:
  std::string name_;
  std::vector<Part> parts_;
  std::vector<double> areas_;
  double total_ = 0;
  Eigen::AlignedBox3d box_;
};

}  // namespace

std::unique_ptr<Shape> make_sphere() {
  return std::make_unique<Sphere>();
}
std::unique_ptr<Shape> make_torus() {
  return std::make_unique<Torus>();
}
std::unique_ptr<Shape> make_rounded_box() {
  return std::make_unique<RoundedBox>();
}

}  // namespace scanclean::bench

namespace scanclean::bench {

std::unique_ptr<Shape> make_thin_plate() {
  // Faces z = +-t(x) / 2, t from 0.01 (x = -0.85) to 0.32 (x = 0.85), y in [-0.5, 0.5].
  const double a = 0.85, b = 0.5, t0 = 0.01, t1 = 0.32;
  std::vector<Eigen::Vector2d> section = {
      {-a, -t0 / 2}, {a, -t1 / 2}, {a, t1 / 2}, {-a, t0 / 2}};  // xz, counter-clockwise
  return std::make_unique<Polyhedron>("thin_plate", prism(section, b));
}

std::unique_ptr<Shape> make_sharp_box() {
  const double x = 0.5, z = 0.2;
  return std::make_unique<Polyhedron>("sharp_box",
                                      prism({{-x, -z}, {x, -z}, {x, z}, {-x, z}}, 0.35));
}

std::unique_ptr<Shape> make_cad_block() {
  return std::make_unique<Polyhedron>(
      "cad_block",
      prism({{-0.5, -0.25}, {0.5, -0.25}, {0.5, 0.05}, {0.0, 0.3}, {-0.5, 0.05}}, 0.3));
}

std::unique_ptr<Shape> make_two_scale() {
  // Before normalisation: a sphere of radius 0.62, tori (outer radius 0.2, tube 0.06) 0.1 above
  // and below it, spheres of radius 0.08 0.1 beside it; everything within 0.88 of the origin.
  std::vector<Composite::Part> parts;
  parts.push_back({make_sphere(), Eigen::Vector3d::Zero(), 0.62});
  parts.push_back({make_torus(), Eigen::Vector3d(0, 0, 0.78), 0.2});
  parts.push_back({make_torus(), Eigen::Vector3d(0, 0, -0.78), 0.2});
  for (int k = 0; k < 4; ++k) {
    const double ang = k * 0.5 * M_PI;
    parts.push_back(
        {make_sphere(), Eigen::Vector3d(0.8 * std::cos(ang), 0.8 * std::sin(ang), 0), 0.08});
  }
  return std::make_unique<Composite>("two_scale", std::move(parts), 1.0 / 0.88);
}

std::vector<std::unique_ptr<Shape>> limit_shapes() {
  std::vector<std::unique_ptr<Shape>> s;
  s.push_back(make_thin_plate());
  s.push_back(make_sharp_box());
  s.push_back(make_cad_block());
  s.push_back(make_two_scale());
  return s;
}

Eigen::Vector3d closest_point(const Shape& s, const Eigen::Vector3d& p) {
  Eigen::Vector3d x = p;
  for (int step = 0; step < 8; ++step) {
    const double d = s.distance(x);
    if (d < 1e-9) break;
    // The unsigned distance's gradient is the unit vector from the nearest surface point to x.
    const double e = std::min(1e-6, 0.25 * d);
    Eigen::Vector3d g;
    for (int a = 0; a < 3; ++a) {
      Eigen::Vector3d u = Eigen::Vector3d::Zero();
      u[a] = e;
      g[a] = s.distance(x + u) - s.distance(x - u);
    }
    const double len = g.norm();
    if (!(len > 0)) break;  // on the medial axis: no unique nearest point
    x -= d * (g / len);
  }
  return x;
}

}  // namespace scanclean::bench

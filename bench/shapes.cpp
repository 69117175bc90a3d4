#include "shapes.h"

#include <algorithm>
#include <array>
#include <cmath>

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

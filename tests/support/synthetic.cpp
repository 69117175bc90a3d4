#include "support/synthetic.h"

#include <array>
#include <cmath>
#include <random>

namespace scanclean::test {

PointCloud noisy_plane(std::size_t n, double size, double sigma, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-size / 2, size / 2);
  std::normal_distribution<double> g(0.0, sigma);
  PointCloud c;
  c.positions.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double x = u(rng), y = u(rng);
    c.positions.emplace_back(x, y, sigma > 0 ? g(rng) : 0.0);
  }
  c.normals.assign(n, Eigen::Vector3f(0, 0, 1));
  return c;
}

PointCloud noisy_sphere(std::size_t n, double radius, double sigma, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g(0.0, 1.0);
  std::normal_distribution<double> noise(0.0, sigma);
  PointCloud c;
  c.positions.reserve(n);
  c.normals.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    Eigen::Vector3d d = draw_point(rng, g, g, g);
    d.normalize();
    Eigen::Vector3d p = radius * d;
    if (sigma > 0) p += draw_point(rng, noise, noise, noise);
    c.positions.push_back(p);
    c.normals.push_back(d.cast<float>());
  }
  return c;
}

std::vector<std::size_t> add_uniform_outliers(PointCloud& cloud, std::size_t count, double lo,
                                              double hi, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(lo, hi);
  std::normal_distribution<double> g(0.0, 1.0);
  std::vector<std::size_t> added;
  for (std::size_t k = 0; k < count; ++k) {
    added.push_back(cloud.positions.size());
    cloud.positions.push_back(draw_point(rng, u, u, u));
    if (!cloud.normals.empty()) {
      const Eigen::Vector3f n = draw_point(rng, g, g, g).cast<float>();
      cloud.normals.push_back(n.normalized());
    }
    if (!cloud.confidences.empty()) cloud.confidences.push_back(1.0f);
  }
  return added;
}

std::vector<std::size_t> add_shell_outliers(PointCloud& cloud, std::size_t count, double radius,
                                            double near, double far, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g(0.0, 1.0);
  std::uniform_real_distribution<double> gap(near, far);
  std::vector<std::size_t> added;
  for (std::size_t k = 0; k < count; ++k) {
    added.push_back(cloud.positions.size());
    const Eigen::Vector3d d = draw_point(rng, g, g, g).normalized();
    cloud.positions.push_back(d * (radius + (k % 2 ? 1 : -1) * gap(rng)));
  }
  return added;
}

RangeFrame coloured_wall_frame(std::uint16_t depth_mm, std::uint8_t red) {
  RangeFrame f;
  f.depth = Image<std::uint16_t>(8, 6, depth_mm);
  f.depth_unit_m = 0.001;
  f.K.fx = f.K.fy = 10;
  f.K.cx = 3.5;
  f.K.cy = 2.5;
  f.K.width = 8;
  f.K.height = 6;
  Image<std::array<std::uint8_t, 3>> rgb(8, 6);
  for (int v = 0; v < 6; ++v)
    for (int u = 0; u < 8; ++u)
      rgb(u, v) = {red, static_cast<std::uint8_t>(10 * u), static_cast<std::uint8_t>(10 * v)};
  f.color = std::move(rgb);
  return f;
}

}  // namespace scanclean::test

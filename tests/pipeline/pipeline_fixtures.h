#pragma once
//! Synthetic depth frames for the pipeline tests: planes seen by a pinhole camera, quantised.

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <random>

#include "scanclean/core/range_frame.h"
#include "scanclean/core/range_source.h"

namespace scanclean::test {

//! A VGA-like pinhole camera scaled to w x h (PS1080 nominal fx = 575.8 at 640 wide).
inline Intrinsics test_camera(int w = 640, int h = 480) {
  Intrinsics K;
  K.width = w;
  K.height = h;
  K.fx = K.fy = 575.8 * w / 640.0;
  K.cx = (w - 1) / 2.0;
  K.cy = (h - 1) / 2.0;
  return K;
}

//! Depth frame (unit `unit_m`) of the plane through (0, 0, z0) with unit normal n (any
//! orientation), rounded to the unit; Gaussian depth noise sigma (metres, seeded) when > 0.
inline RangeFrame plane_frame(const Intrinsics& K, double z0, const Eigen::Vector3d& n,
                              double unit_m = 0.001, double sigma = 0, std::uint32_t seed = 1,
                              std::uint64_t index = 0) {
  RangeFrame f;
  f.index = index;
  f.device_ts_us = static_cast<std::int64_t>(index) * 33333;
  f.K = K;
  f.depth_unit_m = unit_m;
  f.depth = Image<std::uint16_t>(K.width, K.height, 0);
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, sigma > 0 ? sigma : 1.0);
  const double d = n.z() * z0;  // n . X = d on the plane
  for (int v = 0; v < K.height; ++v)
    for (int u = 0; u < K.width; ++u) {
      const Eigen::Vector3d ray((u - K.cx) / K.fx, (v - K.cy) / K.fy, 1.0);
      const double den = n.dot(ray);
      if (std::abs(den) < 1e-9) continue;
      double z = d / den;
      if (sigma > 0) z += noise(rng);
      if (z <= 0) continue;
      const double q = std::round(z / unit_m);
      if (q >= 1 && q <= 65535) f.depth(u, v) = static_cast<std::uint16_t>(q);
    }
  return f;
}

//! Unit normal of a plane tilted by `deg` about the x axis, facing the camera at tilt 0.
inline Eigen::Vector3d tilted_normal(double deg) {
  const double a = deg * M_PI / 180.0;
  return Eigen::Vector3d(0, std::sin(a), -std::cos(a));
}

inline SourceInfo primesense_info(const Intrinsics& K) {
  SourceInfo info;
  info.uri = "synthetic";
  info.kind = "test";
  info.K = K;
  info.noise_model = "nguyen2012";
  return info;
}

}  // namespace scanclean::test

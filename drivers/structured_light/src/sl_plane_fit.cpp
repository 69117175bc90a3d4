#include "scanclean/drivers/sl_plane_fit.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <random>

#include "scanclean/core/errors.h"

namespace scanclean {
namespace {

PlaneFit fit_indices(const std::vector<Eigen::Vector3d>& pts, const std::vector<std::size_t>& idx) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (std::size_t i : idx) mean += pts[i];
  mean /= static_cast<double>(idx.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (std::size_t i : idx) {
    const Eigen::Vector3d d = pts[i] - mean;
    cov += d * d.transpose();
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov);
  PlaneFit f;
  f.normal = es.eigenvectors().col(0).normalized();
  f.offset = -f.normal.dot(mean);
  double s = 0;
  for (std::size_t i : idx) s += f.distance(pts[i]) * f.distance(pts[i]);
  f.rms = std::sqrt(s / static_cast<double>(idx.size()));
  f.inliers = idx;
  return f;
}

}  // namespace

PlaneFit fit_plane_least_squares(const std::vector<Eigen::Vector3d>& points) {
  if (points.size() < 3) throw OptionError("plane fit: need at least 3 points");
  std::vector<std::size_t> idx(points.size());
  for (std::size_t i = 0; i < idx.size(); ++i) idx[i] = i;
  return fit_indices(points, idx);
}

PlaneFit fit_plane_robust(const std::vector<Eigen::Vector3d>& pts, const PlaneFitOptions& o) {
  if (!(o.inlier_threshold > 0)) throw OptionError("plane fit: inlier threshold must be > 0 m");
  if (o.ransac_iterations <= 0) throw OptionError("plane fit: RANSAC iterations must be > 0");
  if (o.refine_iterations < 0) throw OptionError("plane fit: refine iterations must be >= 0");
  if (pts.size() < 3) throw OptionError("plane fit: need at least 3 points");
  std::mt19937_64 rng(o.seed);
  // Score hypotheses on a fixed subsample (at most 20000 points) for speed.
  std::vector<std::size_t> sample;
  const std::size_t stride = std::max<std::size_t>(1, pts.size() / 20000);
  for (std::size_t i = 0; i < pts.size(); i += stride) sample.push_back(i);
  std::uniform_int_distribution<std::size_t> pick(0, pts.size() - 1);
  Eigen::Vector3d best_n = Eigen::Vector3d::UnitZ();
  double best_d = 0;
  std::size_t best_count = 0;
  for (int it = 0; it < o.ransac_iterations; ++it) {
    const Eigen::Vector3d& a = pts[pick(rng)];
    const Eigen::Vector3d& b = pts[pick(rng)];
    const Eigen::Vector3d& c = pts[pick(rng)];
    Eigen::Vector3d n = (b - a).cross(c - a);
    if (n.norm() < 1e-12) continue;
    n.normalize();
    const double d = -n.dot(a);
    std::size_t count = 0;
    for (std::size_t i : sample) count += std::abs(n.dot(pts[i]) + d) < o.inlier_threshold;
    if (count > best_count) {
      best_count = count;
      best_n = n;
      best_d = d;
    }
  }
  PlaneFit f;
  f.normal = best_n;
  f.offset = best_d;
  for (int round = 0; round <= o.refine_iterations; ++round) {
    std::vector<std::size_t> in;
    for (std::size_t i = 0; i < pts.size(); ++i)
      if (std::abs(f.distance(pts[i])) < o.inlier_threshold) in.push_back(i);
    if (in.size() < 3) break;
    f = fit_indices(pts, in);
  }
  return f;
}

}  // namespace scanclean

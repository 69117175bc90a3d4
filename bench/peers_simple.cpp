#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Eigenvalues>
#include <cmath>

#include "kdtree.h"
#include "peers.h"

namespace scanclean::bench {

namespace {
template <class F>
void parallel_each(std::size_t n, F&& f) {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 512),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      std::vector<std::uint32_t> idx;
                      std::vector<double> d2;
                      for (std::size_t i = r.begin(); i != r.end(); ++i) f(i, idx, d2);
                    });
}
}  // namespace

Points pca_plane_projection(const Points& in, int k) {
  Points out(in.size());
  if (in.empty()) return out;
  KdTree tree(in);
  parallel_each(in.size(),
                [&](std::size_t i, std::vector<std::uint32_t>& idx, std::vector<double>& d2) {
                  tree.knn(in[i], static_cast<std::size_t>(k), idx, d2);
                  Eigen::Vector3d c = Eigen::Vector3d::Zero();
                  for (auto j : idx) c += in[j];
                  c /= static_cast<double>(idx.size());
                  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
                  for (auto j : idx) {
                    const Eigen::Vector3d d = in[j] - c;
                    cov += d * d.transpose();
                  }
                  if (idx.size() < 3) {
                    out[i] = in[i];
                    return;
                  }
                  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
                  es.computeDirect(cov);
                  const Eigen::Vector3d n = es.eigenvectors().col(0);  // smallest eigenvalue first
                  out[i] = in[i] - ((in[i] - c).dot(n)) * n;
                });
  return out;
}

std::vector<std::uint8_t> statistical_outlier_removal(const Points& in, int k, double std_ratio) {
  std::vector<std::uint8_t> keep(in.size(), 1);
  if (in.size() < 2) return keep;
  KdTree tree(in);
  std::vector<double> mean_d(in.size());
  parallel_each(in.size(),
                [&](std::size_t i, std::vector<std::uint32_t>& idx, std::vector<double>& d2) {
                  tree.knn(in[i], static_cast<std::size_t>(k) + 1, idx, d2);
                  double s = 0;
                  std::size_t cnt = 0;
                  for (std::size_t j = 0; j < idx.size(); ++j) {
                    if (idx[j] == i) continue;  // the query point itself
                    if (cnt == static_cast<std::size_t>(k)) break;
                    s += std::sqrt(d2[j]);
                    ++cnt;
                  }
                  mean_d[i] = cnt ? s / static_cast<double>(cnt) : 0.0;
                });
  double sum = 0, sq = 0;
  for (double d : mean_d) {
    sum += d;
    sq += d * d;
  }
  const double n = static_cast<double>(in.size());
  const double mean = sum / n;
  const double var = std::max(0.0, (sq - sum * sum / n) / (n - 1));
  const double limit = mean + std_ratio * std::sqrt(var);
  for (std::size_t i = 0; i < in.size(); ++i) keep[i] = mean_d[i] <= limit ? 1 : 0;
  return keep;
}

}  // namespace scanclean::bench

#include "protocol.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>

namespace scanclean::bench {

namespace {

template <class F>
void parallel_each(std::size_t n, F&& f) {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 1024),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i != r.end(); ++i) f(i);
                    });
}

double mean_of(const std::vector<double>& v) {
  if (v.empty()) return 0;
  double s = 0;
  for (double x : v) s += x;  // sequential: deterministic for any thread count
  return s / static_cast<double>(v.size());
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  const std::size_t k =
      std::min(v.size() - 1, static_cast<std::size_t>(std::ceil(q * v.size())) - (q > 0 ? 1 : 0));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

Eigen::Vector3d uniform_in(const Eigen::AlignedBox3d& box, Rng& rng) {
  Eigen::Vector3d p;
  for (int i = 0; i < 3; ++i) p[i] = rng.uniform(box.min()[i], box.max()[i]);
  return p;
}

}  // namespace

void normalise_unit_sphere(std::vector<Eigen::Vector3d>& points) {
  if (points.empty()) return;
  Eigen::AlignedBox3d box;
  for (const auto& p : points) box.extend(p);
  const Eigen::Vector3d c = box.center();
  double r = 0;
  for (const auto& p : points) r = std::max(r, (p - c).norm());
  if (r <= 0) throw std::invalid_argument("normalise_unit_sphere: all points coincide");
  for (auto& p : points) p = (p - c) / r;
}

Instance make_instance(const Shape& shape, const InstanceSpec& spec) {
  Instance inst;
  Rng rng(spec.seed);
  inst.clean = shape.sample(spec.n, rng);
  std::vector<Eigen::Vector3d> pts = inst.clean;
  for (auto& p : pts) p += spec.sigma * Eigen::Vector3d(rng.normal(), rng.normal(), rng.normal());
  std::vector<std::uint8_t> label(pts.size(), 0);
  const Eigen::AlignedBox3d box = shape.box();
  const double dmin = std::max(5 * spec.sigma, 0.05);
  inst.outlier_min_distance = dmin;
  const auto target =
      static_cast<std::size_t>(std::llround(spec.outlier_fraction * static_cast<double>(spec.n)));
  if (spec.outliers == OutlierKind::kUniform) {
    while (inst.outlier_count < target) {
      const Eigen::Vector3d p = uniform_in(box, rng);
      if (shape.distance(p) < dmin) continue;
      pts.push_back(p);
      label.push_back(1);
      ++inst.outlier_count;
    }
  } else if (spec.outliers == OutlierKind::kClumps) {
    constexpr double kClumpStd = 0.02;
    while (inst.outlier_count < target) {
      const Eigen::Vector3d c = uniform_in(box, rng);
      if (shape.distance(c) < dmin + 3 * kClumpStd) continue;
      const std::size_t m = 20 + rng.index(31);  // 20..50 points
      for (std::size_t j = 0; j < m; ++j) {
        pts.push_back(c + kClumpStd * Eigen::Vector3d(rng.normal(), rng.normal(), rng.normal()));
        label.push_back(1);
      }
      inst.outlier_count += m;
    }
  }
  // Shuffle (Fisher-Yates with our generator) so that no method can exploit the order.
  std::vector<std::size_t> order(pts.size());
  std::iota(order.begin(), order.end(), 0);
  for (std::size_t i = order.size(); i > 1; --i) std::swap(order[i - 1], order[rng.index(i)]);
  inst.input.resize(pts.size());
  inst.is_outlier.resize(pts.size());
  for (std::size_t i = 0; i < order.size(); ++i) {
    inst.input[i] = pts[order[i]];
    inst.is_outlier[i] = label[order[i]];
  }
  return inst;
}

GroundTruth::GroundTruth(const Shape& shape, std::vector<Eigen::Vector3d> clean,
                         std::size_t dense_n, std::uint64_t seed)
    : shape_(shape), clean_(std::move(clean)) {
  Rng rng(seed);
  dense_ = shape.sample(dense_n, rng);
  clean_tree_ = std::make_unique<KdTree>(clean_);
  std::vector<double> d(dense_.size());
  parallel_each(dense_.size(),
                [&](std::size_t i) { d[i] = std::sqrt(clean_tree_->nearest(dense_[i]).second); });
  coverage_tol_ = percentile(std::move(d), 0.99);
}

Metrics evaluate(const GroundTruth& gt, const std::vector<Eigen::Vector3d>& output,
                 const Classification& cls) {
  const Instance* instance = cls.instance;
  const std::vector<std::uint8_t>* kept = cls.kept;
  Metrics m;
  m.n_out = output.size();
  if (instance != nullptr && kept != nullptr) {
    if (kept->size() != instance->input.size())
      throw std::logic_error("evaluate: kept mask size differs from the input size");
    std::size_t removed = 0, removed_out = 0, kept_in = 0, inliers = 0;
    for (std::size_t i = 0; i < kept->size(); ++i) {
      const bool out = instance->is_outlier[i] != 0;
      if (!(*kept)[i]) {
        ++removed;
        if (out) ++removed_out;
      } else if (!out) {
        ++kept_in;
      } else {
        m.farthest_kept_outlier =
            std::max(m.farthest_kept_outlier, gt.shape().distance(instance->input[i]));
      }
      if (!out) ++inliers;
    }
    m.classified = true;
    m.removed = removed;
    m.precision = removed ? static_cast<double>(removed_out) / removed : 1.0;
    m.recall = instance->outlier_count
                   ? static_cast<double>(removed_out) / static_cast<double>(instance->outlier_count)
                   : 1.0;
    m.retention = inliers ? static_cast<double>(kept_in) / inliers : 1.0;
    if (cls.input_to_output != nullptr) {
      std::size_t neutralised = 0;
      for (std::size_t i = 0; i < kept->size(); ++i) {
        if (!instance->is_outlier[i]) continue;
        const std::int64_t o = (*cls.input_to_output)[i];
        if (o < 0 || gt.shape().distance(output[static_cast<std::size_t>(o)]) <= cls.near_surface)
          ++neutralised;
      }
      m.effective_recall =
          instance->outlier_count
              ? static_cast<double>(neutralised) / static_cast<double>(instance->outlier_count)
              : 1.0;
    }
  }
  if (output.empty()) {
    m.cd = m.p2m = m.mean_dist = m.p95_dist = m.rms_dist = std::nan("");
    return m;
  }
  KdTree out_tree(output);
  std::vector<double> o2clean(output.size()), o2surf(output.size());
  parallel_each(output.size(), [&](std::size_t i) {
    o2clean[i] = gt.clean_tree().nearest(output[i]).second;
    o2surf[i] = gt.shape().distance(output[i]);
  });
  std::vector<double> clean2o(gt.clean().size());
  parallel_each(gt.clean().size(),
                [&](std::size_t i) { clean2o[i] = out_tree.nearest(gt.clean()[i]).second; });
  std::vector<double> dense2o(gt.dense().size());
  parallel_each(gt.dense().size(),
                [&](std::size_t i) { dense2o[i] = out_tree.nearest(gt.dense()[i]).second; });

  std::vector<double> o2surf_sq(o2surf.size());
  for (std::size_t i = 0; i < o2surf.size(); ++i) o2surf_sq[i] = o2surf[i] * o2surf[i];
  m.cd = 1e4 * (mean_of(o2clean) + mean_of(clean2o));
  m.p2m = 1e4 * (mean_of(o2surf_sq) + mean_of(dense2o));
  m.mean_dist = mean_of(o2surf);
  m.rms_dist = std::sqrt(mean_of(o2surf_sq));
  m.p95_dist = percentile(o2surf, 0.95);
  const double tol2 = gt.coverage_tolerance() * gt.coverage_tolerance();
  std::size_t covered = 0;
  for (double d2 : dense2o) covered += d2 <= tol2 ? 1 : 0;
  m.coverage = static_cast<double>(covered) / static_cast<double>(dense2o.size());
  if (gt.edge_band() > 0 && gt.shape().has_creases()) {
    std::vector<std::uint8_t> in_band(output.size());
    parallel_each(output.size(), [&](std::size_t i) {
      in_band[i] = gt.shape().crease_distance(output[i]) < gt.edge_band() ? 1 : 0;
    });
    double sum = 0, sq = 0;
    for (std::size_t i = 0; i < output.size(); ++i) {
      if (!in_band[i]) continue;
      ++m.edge_n;
      sum += o2surf[i];
      sq += o2surf_sq[i];
    }
    if (m.edge_n > 0) {
      m.edge_mean = sum / static_cast<double>(m.edge_n);
      m.edge_rms = std::sqrt(sq / static_cast<double>(m.edge_n));
    }
  }
  return m;
}

}  // namespace scanclean::bench

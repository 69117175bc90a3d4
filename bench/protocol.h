#pragma once
//! \file protocol.h
//! The evaluation protocol of docs/ALGORITHM.md: noisy inputs with known ground truth, and the
//! quality metrics (CD, P2M, point-to-surface statistics, coverage, outlier classification).

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "kdtree.h"
#include "shapes.h"

namespace scanclean::bench {

enum class OutlierKind { kNone, kUniform, kClumps };

struct InstanceSpec {
  std::size_t n = 10000;  //!< surface points (before outliers)
  double sigma = 0.01;    //!< isotropic Gaussian noise, normalised units
  OutlierKind outliers = OutlierKind::kNone;
  double outlier_fraction = 0;  //!< uniform: share of n; clumps: total clump points / n
  std::uint64_t seed = 1;
};

//! One benchmark input with its ground truth.
struct Instance {
  std::vector<Eigen::Vector3d> clean;    //!< the n noise-free surface samples (CD's GT sample)
  std::vector<Eigen::Vector3d> input;    //!< noisy samples and injected outliers, shuffled
  std::vector<std::uint8_t> is_outlier;  //!< per input point: 1 = injected outlier
  std::size_t outlier_count = 0;
  double outlier_min_distance = 0;  //!< injected outliers are at least this far from the surface
};

//! Builds an instance. Uniform outliers: uniform in the shape's bounding box, rejected when closer
//! than max(5 sigma, 0.05) to the surface (closer ones are indistinguishable from noise). Clumps:
//! groups of 20-50 points (Gaussian, std 0.02 around a centre uniform in the box and at least
//! max(5 sigma, 0.05) + 0.06 from the surface) until the total reaches outlier_fraction * n.
Instance make_instance(const Shape& shape, const InstanceSpec& spec);

//! What the metrics need of the ground truth: the clean sample (CD), a dense independent sample
//! (P2M's mesh -> output term and coverage), and the shape (exact point-to-surface distance).
class GroundTruth {
 public:
  GroundTruth(const Shape& shape, std::vector<Eigen::Vector3d> clean, std::size_t dense_n,
              std::uint64_t seed);
  const Shape& shape() const { return shape_; }
  const std::vector<Eigen::Vector3d>& clean() const { return clean_; }
  const std::vector<Eigen::Vector3d>& dense() const { return dense_; }
  const KdTree& clean_tree() const { return *clean_tree_; }
  //! Coverage tolerance: the 99th percentile of the distance from the dense sample to the clean
  //! sample, so the clean, noise-free input itself has 99 % coverage.
  double coverage_tolerance() const { return coverage_tol_; }
  //! Edge band of the edge-band metric (shapes with creases): output points whose nearest
  //! surface point lies within this distance of a crease; 0 = no edge metric.
  double edge_band() const { return edge_band_; }
  void set_edge_band(double band) { edge_band_ = band; }

 private:
  const Shape& shape_;
  std::vector<Eigen::Vector3d> clean_;
  std::vector<Eigen::Vector3d> dense_;
  std::unique_ptr<KdTree> clean_tree_;
  double coverage_tol_ = 0;
  double edge_band_ = 0;
};

struct Metrics {
  std::size_t n_out = 0;
  double cd = 0;         //!< x 1e4, squared distances
  double p2m = 0;        //!< x 1e4, squared distances
  double mean_dist = 0;  //!< mean |output point -> surface|
  double p95_dist = 0;   //!< 95th percentile of the same
  double rms_dist = 0;   //!< RMS of the same, over ALL output points
  double coverage = 0;   //!< share of the dense sample within coverage_tolerance of the output
  //! Edge band (GroundTruth::edge_band() > 0 and a shape with creases): RMS and mean distance to
  //! the surface of the output points whose nearest surface point is within the band of a
  //! crease, and their count.
  double edge_rms = std::nan("");
  double edge_mean = std::nan("");
  std::size_t edge_n = 0;
  // Outlier classification (only when labels are given).
  bool classified = false;
  std::size_t removed = 0;
  double precision = 0;              //!< removed outliers / removed points (1 if nothing removed)
  double recall = 0;                 //!< removed outliers / injected outliers
  double retention = 0;              //!< kept inliers / inliers
  double farthest_kept_outlier = 0;  //!< largest surface distance of a kept injected outlier
  //! Share of injected outliers that are removed OR whose output point ends up within
  //! `near_surface` of the true surface (a filter that projects an outlier onto the surface has
  //! neutralised it); only when the input -> output map is given.
  double effective_recall = std::nan("");
};

//! Outlier classification inputs for evaluate().
struct Classification {
  const Instance* instance = nullptr;
  const std::vector<std::uint8_t>* kept = nullptr;  //!< per input point: 1 = kept
  //! Optional: per input point, the index of its output point (-1 if removed).
  const std::vector<std::int64_t>* input_to_output = nullptr;
  double near_surface = 0;  //!< distance for effective_recall
};

//! Metrics of `output` against the ground truth. If classification.instance and .kept are given,
//! the outlier classification is filled in. Deterministic;
//! parallel inside.
Metrics evaluate(const GroundTruth& gt, const std::vector<Eigen::Vector3d>& output,
                 const Classification& classification = {});

//! Normalises points in place: bounding-box centre to the origin, farthest point at radius 1.
void normalise_unit_sphere(std::vector<Eigen::Vector3d>& points);

}  // namespace scanclean::bench

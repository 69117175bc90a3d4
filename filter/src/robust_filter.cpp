#include "scanclean/filter/robust_filter.h"

#include <tbb/info.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "clustering.h"
#include "huge_pages.h"
#include "input_checks.h"
#include "input_groups.h"
#include "kernel_sites.h"
#include "kernels.h"
#include "neighbor_index.h"
#include "orientation.h"
#include "outlier_tests.h"
#include "outputs.h"
#include "parallel.h"
#include "point_set.h"
#include "projection.h"
#include "scale.h"
#include "scanclean/core/errors.h"
#include "scanclean/core/process_memory.h"

namespace scanclean {
namespace {

using detail::Clock;
using detail::parallel_each;
using detail::seconds_since;

// Throws InputError for a non-finite coordinate or a confidence outside [0, 1]; returns whether
// the input's confidences are the weights and its normals the sensor normals.
void check_input(const PointCloud& input, const FilterOptions& o, bool& use_w, bool& use_v) {
  const std::size_t N = input.size();
  if (N >= 0xffffffffULL) throw InputError("filter: more than 4 billion points are not supported");
  use_w = o.use_confidences && input.has_confidences();
  if (use_w && input.confidences.size() != N)
    throw InputError("filter input", "confidences", "one confidence per point");
  const detail::InvalidPoint bad = detail::first_invalid_point(input, use_w);
  if (bad.index < N)
    throw InputError("filter input", "point " + std::to_string(bad.index), bad.what);
  use_v = o.use_sensor_normals && input.has_normals() && input.normals.size() == N;
}

// The input points relative to `origin`, with unit sensor normals (zero where invalid) and
// weights, in input order.
detail::PointSet input_points(const PointCloud& input, const Eigen::Vector3d& origin, bool use_v,
                              bool use_w) {
  const std::size_t N = input.size();
  detail::PointSet in;
  detail::resize_huge(in.p, N);
  parallel_each(N, [&](std::size_t i) { in.p[i] = input.positions[i] - origin; });
  if (use_v) {
    detail::resize_huge(in.v, N);
    parallel_each(N, [&](std::size_t i) {
      const Eigen::Vector3f v = input.normals[i];
      const float len = v.norm();
      in.v[i] =
          (std::isfinite(len) && len > 1e-6f) ? Eigen::Vector3f(v / len) : Eigen::Vector3f::Zero();
    });
  }
  if (use_w) in.w = input.confidences;
  return in;
}

// Reorders `in` into the index order `order` (order[s] = input index of point s), freeing it.
detail::PointSet reorder(detail::PointSet& in, const std::vector<std::uint32_t>& order) {
  detail::PointSet d;
  d.h = in.h;
  d.v_orients_only = in.v_orients_only;
  auto move_into = [&](auto& from, auto& to) {
    if (from.empty()) return;
    to = detail::permuted(from, order);
    std::remove_reference_t<decltype(from)>().swap(from);
  };
  move_into(in.p, d.p);
  move_into(in.v, d.v);
  move_into(in.w, d.w);
  move_into(in.hi, d.hi);
  return d;
}

// The kernel stride: kernels at every stride-th point when the neighbourhoods hold more than
// K_h points (FilterOptions::kernel_stride).
std::size_t kernel_stride(const FilterOptions& o, double h, double h0) {
  if (o.kernel_stride > 0) return static_cast<std::size_t>(o.kernel_stride);
  if (o.scale == ScaleMode::kAuto && h0 > 0)  // about K_h kernels within h
    return static_cast<std::size_t>(std::clamp(std::floor((h / h0) * (h / h0)), 1.0, 64.0));
  if (o.scale == ScaleMode::kAdaptive)  // the same: k_adaptive points within h_i
    return static_cast<std::size_t>(std::clamp(o.k_adaptive / o.k_h, 1, 64));
  return 1;
}

// The second pass (FilterOptions::passes): kernels rebuilt from the supported output points of
// the first, which are projected again; x and pr are updated in place.
void second_pass(const detail::PointSet& d, const detail::KernelParams& prm, const FilterOptions& o,
                 bool use_v, std::vector<Eigen::Vector3d>& x, detail::Projected& pr,
                 FilterStats& st) {
  using detail::ProjectionState;
  auto t = Clock::now();
  const std::size_t N = x.size();
  std::vector<std::uint32_t> sub;
  for (std::size_t i = 0; i < N; ++i)
    if (detail::projected(pr.state[i])) sub.push_back(static_cast<std::uint32_t>(i));
  detail::PointSet d2;
  d2.h = d.h;
  d2.v_orients_only = d.v_orients_only;
  d2.p.resize(sub.size());
  std::vector<Eigen::Vector3f> pf2(sub.size());
  for (std::size_t k = 0; k < sub.size(); ++k) {
    d2.p[k] = x[sub[k]];
    pf2[k] = x[sub[k]].cast<float>();
  }
  if (!d.v.empty())
    for (std::uint32_t i : sub) d2.v.push_back(d.v[i]);
  if (!d.w.empty())
    for (std::uint32_t i : sub) d2.w.push_back(d.w[i]);
  if (!d.hi.empty())
    for (std::uint32_t i : sub) d2.hi.push_back(d.hi[i]);
  auto index2 = std::make_unique<NeighborIndex>(std::move(pf2), grid_cell_for(prm.cell));
  std::vector<Eigen::Vector3f> nref2;
  // The sheet refit's and the crease split's triggers compare a kernel's residual spread with
  // the noise sigma. The points here are the first pass's output, whose spread across the
  // surface is a small part of the input's noise, below the eigenvalue floor (a 50k-point
  // sharp box at 2 % noise: RMS 0.0023 from its faces, against 0.0156 estimated on the input
  // and a floor of 0.0066). Against the input's sigma, 17 kernels asked for the split here
  // (3,017 in the first pass) and the second pass rounded the creases the first had kept; so
  // here the triggers use the floor, eigen_floor x h (2,545 split).
  detail::KernelParams prm2 = prm;
  if (prm.noise_sigma > 0) prm2.noise_sigma = o.eigen_floor * d.h;
  detail::KernelSet ks2 = detail::build_kernels(d2, index2, detail::PointIndexIds::kIds, prm2,
                                                nref2, "kernels (pass 2)");
  st.kernels_refitted += ks2.refitted;
  st.kernels_split += ks2.split;
  st.seconds_kernels += seconds_since(t);
  t = Clock::now();
  std::vector<Eigen::Vector3d> x2 = d2.p;
  detail::Projected pr2;
  detail::project_all(d2, ks2, nref2, o, false, use_v, std::vector<std::uint8_t>(d2.p.size(), 0),
                      x2, pr2, "projection (pass 2)");
  for (std::size_t k = 0; k < sub.size(); ++k) {
    const std::uint32_t i = sub[k];
    x[i] = x2[k];
    pr.L[i] = pr2.L[k];
    pr.iterations[i] = static_cast<std::uint8_t>(
        std::min(255, static_cast<int>(pr.iterations[i]) + pr2.iterations[k]));
    pr.state[i] = pr2.state[k];
    if (pr2.state[k] != ProjectionState::kUnsupported) pr.normal[i] = pr2.normal[k];
  }
  st.seconds_projection += seconds_since(t);
}

// Mean and 95th percentile of the iteration counts, and the points not converged, over the
// projected points.
void iteration_stats(const detail::Projected& pr, FilterStats& st) {
  std::array<std::size_t, 256> hist{};
  std::size_t supported = 0;
  double sum = 0;
  for (std::size_t i = 0; i < pr.state.size(); ++i) {
    if (!detail::projected(pr.state[i])) continue;
    ++supported;
    ++hist[pr.iterations[i]];
    sum += pr.iterations[i];
    if (pr.state[i] == detail::ProjectionState::kNotConverged) ++st.not_converged;
  }
  st.mean_iterations = supported ? sum / static_cast<double>(supported) : 0;
  std::size_t acc = 0;
  const double target = 0.95 * static_cast<double>(supported);
  for (int k = 0; k < 256 && supported; ++k) {
    acc += hist[k];
    if (static_cast<double>(acc) >= target) {
      st.p95_iterations = k;
      break;
    }
  }
}

// The filter on one group of distinct points (input_groups.h), in the order of the paper's
// outline. Three index spaces: input points (input order), points (the grid order of the spatial
// sort; input_index maps a point to its input index) and representatives (clusters).
// `multiplicity` (optional): the input points each point stands for.
FilterResult run_group(const PointCloud& input, const FilterOptions& o, bool use_w, bool use_v,
                       const std::vector<std::uint32_t>* multiplicity) {
  FilterResult result;
  FilterStats& st = result.stats;
  const std::size_t N = input.size();
  st.points_in = N;

  // 1. Scale: h (or h_i), in a local frame around the bounding box's centre.
  auto t = Clock::now();
  detail::report(o, "scale", 0);
  const Eigen::AlignedBox3d box = detail::bounding_box_of(input.positions);
  const Eigen::Vector3d origin = box.center();
  std::vector<Eigen::Vector3f> pf;
  detail::resize_huge(pf, N);
  parallel_each(N, [&](std::size_t i) { pf[i] = (input.positions[i] - origin).cast<float>(); });
  detail::PointSet in = input_points(input, origin, use_v, use_w);
  in.v_orients_only = o.normals_orient_only;
  if (o.orient_k > 0 && !use_v) {
    // A cloud without normals in use gets oriented ones first (orientation.h); from here on the
    // filter runs as on input normals that only orient.
    const auto t_orient = Clock::now();
    std::optional<Eigen::Vector3f> viewpoint;
    if (o.orient_viewpoint)
      viewpoint = (Eigen::Vector3d((*o.orient_viewpoint)[0], (*o.orient_viewpoint)[1],
                                   (*o.orient_viewpoint)[2]) -
                   origin)
                      .cast<float>();
    detail::OrientedPointNormals on = detail::orient_normals(pf, o.orient_k, o, viewpoint);
    in.v = std::move(on.normals);
    in.v_orients_only = true;
    use_v = true;
    st.orientation_trees = on.trees;
    st.seconds_orientation = seconds_since(t_orient);
  }
  detail::ScaleChoice scale = detail::choose_scale(in, pf, box.diagonal().norm(), use_v, o);
  const double h = scale.h;
  st.h = h;
  st.h_min = scale.h_min;
  st.h_max = scale.h_max;
  st.h0 = scale.h0;
  st.noise_sigma = scale.noise_sigma;
  st.noise_sigma_h0 = scale.noise_sigma_h0;
  st.h_noise = scale.h_noise;
  st.scale_crease_samples = scale.crease_samples;
  const int K = o.scale == ScaleMode::kAdaptive ? o.k_adaptive : o.k_h;
  // Spacing from the neighbour distance h0 (kAuto), not from an h the noise has raised.
  st.mean_spacing =
      (o.scale == ScaleMode::kAuto ? st.h0 : h) / std::sqrt(static_cast<double>(K) / M_PI);
  st.merge_eps = o.merge_eps < 0 ? 0.25 * st.mean_spacing : o.merge_eps;
  std::unique_ptr<NeighborIndex> index = std::move(scale.index);
  if (!index) index = std::make_unique<NeighborIndex>(std::move(pf), grid_cell_for(scale.h_grid));
  std::vector<Eigen::Vector3f>().swap(pf);
  if (o.scale == ScaleMode::kFixed) detail::check_fixed_scale(*index, h);
  // Spatial sort: everything from here on is stored and processed in grid order.
  const std::vector<std::uint32_t> input_index = index->order();
  detail::PointSet d = reorder(in, input_index);
  st.seconds_scale = seconds_since(t) - st.seconds_orientation;

  // 2. Kernels: a weighted PCA per point (or every stride-th), frozen.
  detail::KernelParams prm;
  prm.options = &o;
  prm.oriented = use_v;
  prm.cell = scale.h_grid;
  prm.kernel_cell = scale.h_grid_kernels;
  prm.gather_factor = detail::candidate_radius(o);
  prm.stride = kernel_stride(o, h, st.h0);
  if (o.scale == ScaleMode::kAuto)
    prm.noise_sigma = std::max(st.noise_sigma, o.eigen_floor * h);
  else if (o.refit_noise_sigma > 0)  // given (a tile of the tiled filter)
    prm.noise_sigma = std::max(o.refit_noise_sigma, o.eigen_floor * h);
  st.kernel_stride = static_cast<int>(prm.stride);
  t = Clock::now();
  std::vector<Eigen::Vector3f> nref;
  prm.keep_fits = o.outlier_sigma > 0;
  std::vector<float> support;
  detail::assign_huge(support, o.tau > 0 ? N : 0, -1.0f);
  if (!support.empty()) prm.support = &support;
  std::vector<std::uint8_t> sites;  // the tiled filter's kernel sites (kernels.h), grid order
  if (const Attribute* a = input.find_attribute(detail::kKernelSitesAttribute)) {
    sites.resize(N);
    for (std::size_t s = 0; s < N; ++s) sites[s] = a->values[input_index[s]] != 0 ? 1 : 0;
    prm.sites = &sites;
  }
  std::vector<std::uint8_t> strides;  // the local kernel strides (kernel_sites.h), grid order
  if (!prm.sites && o.kernel_stride == 0 && o.scale != ScaleMode::kAdaptive) {
    strides = detail::local_kernel_strides(*index, prm.stride);
    prm.strides = &strides;
  }
  detail::KernelSet ks =
      detail::build_kernels(d, index, detail::PointIndexIds::kSlots, prm, nref, "kernels");
  prm.keep_fits = false;
  prm.support = nullptr;
  prm.sites = nullptr;
  prm.strides = nullptr;
  std::vector<std::uint8_t>().swap(sites);
  std::vector<Eigen::Vector3d> x = std::move(d.p);  // projected positions, initially the input
  st.kernels = ks.fitted;
  st.kernels_refitted = ks.refitted;
  st.kernels_split = ks.split;
  st.seconds_kernels += seconds_since(t);

  // 3. Projection, after the density test on each point's own kernel support and, point by
  // point, the off-surface test.
  t = Clock::now();
  if (o.passes == 1 && !d.v.empty()) {
    // Sensor normals are only needed as reference normals from here on: fold them into nref
    // and free them (memory).
    for (std::size_t i = 0; i < N; ++i)
      if (d.has_v(i)) nref[i] = d.v[i];
    std::vector<Eigen::Vector3f>().swap(d.v);
  }
  std::vector<std::uint8_t> sparse =
      detail::sparse_support(support, o.tau, strides.empty() ? nullptr : &strides);
  if (sparse.empty()) sparse.assign(N, 0);
  std::vector<float>().swap(support);
  std::vector<std::uint8_t>().swap(strides);
  detail::Projected pr;
  detail::project_all(d, ks, nref, o, true, use_v, sparse, x, pr, "projection");
  st.seconds_projection += seconds_since(t);
  std::vector<std::uint8_t>().swap(sparse);
  ks = detail::KernelSet{};
  if (o.passes >= 2) second_pass(d, prm, o, use_v, x, pr, st);
  iteration_stats(pr, st);

  // 4. Clustering of the converged points.
  t = Clock::now();
  detail::report(o, "clustering", 0);
  const detail::Clusters cl = detail::cluster_points(x, pr, st.merge_eps, use_v);
  st.seconds_clustering = seconds_since(t);
  detail::report(o, "clustering", 1);

  // 5. Outlier tests on the representatives.
  t = Clock::now();
  detail::report(o, "outliers", 0);
  detail::RepresentativeTestInput ti;
  ti.clusters = &cl;
  ti.x = &x;
  ti.projected = &pr;
  ti.points = &d;
  ti.input_positions = &input.positions;
  ti.input_index = &input_index;
  ti.origin = origin;
  ti.cell = prm.cell;
  ti.stride = prm.stride;
  ti.points_in = N;
  const std::vector<detail::Removal> removal = detail::test_representatives(ti, o);

  // 6. Outputs.
  detail::OutputInput oi;
  oi.input = &input;
  oi.clusters = &cl;
  oi.removal = &removal;
  oi.projected = &pr;
  oi.input_index = &input_index;
  oi.origin = origin;
  oi.multiplicity = multiplicity;
  detail::write_outputs(oi, result);
  st.seconds_outliers = seconds_since(t);
  detail::report(o, "outliers", 1);
  return result;
}

// The filter on distinct points: the bulk and, separately, the points far from it
// (input_groups.h).
FilterResult run_split(const PointCloud& input, const FilterOptions& o, bool use_w, bool use_v,
                       const std::vector<std::uint32_t>* multiplicity) {
  const detail::FarSplit split = detail::split_far_points(input);
  if (split.far.empty()) return run_group(input, o, use_w, use_v, multiplicity);
  auto part = [&](const std::vector<std::size_t>& idx, auto&& filter) {
    PointCloud sub = select(input, idx);
    sub.grid = OrganizedGrid{};
    std::vector<std::uint32_t> mult;
    if (multiplicity)
      for (std::size_t i : idx) mult.push_back((*multiplicity)[i]);
    return filter(sub, multiplicity ? &mult : nullptr);
  };
  std::vector<FilterResult> parts;
  parts.push_back(part(split.near, [&](const PointCloud& c, const std::vector<std::uint32_t>* m) {
    return run_group(c, o, use_w, use_v, m);
  }));
  parts.push_back(part(split.far, [&](const PointCloud& c, const std::vector<std::uint32_t>* m) {
    return run_split(c, o, use_w, use_v, m);
  }));
  return detail::merge_parts(std::move(parts), {split.near, split.far});
}

FilterResult run(const PointCloud& input, const FilterOptions& o) {
  const auto t_start = Clock::now();
  const std::size_t N = input.size();
  FilterResult result;
  if (N > 0) {
    bool use_w = false, use_v = false;
    check_input(input, o, use_w, use_v);
    const detail::Coincident coincident = detail::find_coincident(input);
    if (coincident.any()) {
      PointCloud distinct = select(input, coincident.first);
      distinct.grid = OrganizedGrid{};
      result = run_split(distinct, o, use_w, use_v, &coincident.count);
      detail::expand_coincident(input, coincident, result);
    } else {
      result = run_split(input, o, use_w, use_v, nullptr);
    }
  }
  result.stats.points_in = N;
  result.stats.threads = tbb::this_task_arena::max_concurrency();
  result.stats.seconds_total = seconds_since(t_start);
  result.stats.peak_rss_bytes = peak_resident_bytes();
  return result;
}

}  // namespace

FilterResult robust_filter(const PointCloud& input, const FilterOptions& options) {
  validate(options);
  try {
    input.check_consistent();
  } catch (const std::logic_error& e) {
    throw InputError("filter input", "point arrays", e.what());
  }
  FilterResult result;
  if (options.threads <= 0) {
    // All cores: the caller's arena. A task_arena of its own, entered from a TBB worker (the
    // live pipeline's cleaning stage), got the other worker only part of the time: a 3dj window
    // took 1.2 s there instead of 0.78 s, with the machine a third idle.
    result = run(input, options);
    return result;
  }
  tbb::task_arena arena(options.threads);
  arena.execute([&] { result = run(input, options); });
  return result;
}

}  // namespace scanclean

#include "filter_run.h"

#include <chrono>
#include <sstream>

#include "scanclean/core/errors.h"

#ifdef SCANCLEAN_BENCH_HAVE_FILTER
#include "scanclean/filter/robust_filter.h"
#endif
#ifdef SCANCLEAN_BENCH_HAVE_MESH_SUITE
#include "scanclean/mesh/surface_reconstruction.h"
#endif

namespace scanclean::bench {

std::string FilterSettings::describe() const {
  std::ostringstream s;
  s << "defaults";
  if (adaptive) s << ", scale=adaptive k=" << k_adaptive;
  if (kernel_stride > 0) s << ", kernel_stride=" << kernel_stride;
  if (refit_spread >= 0) s << ", refit_spread=" << refit_spread;
  if (crease_spread >= 0) s << ", crease_spread=" << crease_spread;
  if (orient_k > 0) s << ", orient_k=" << orient_k;
  if (cgal_orient_k > 0) s << ", CGAL normals (PCA k=" << cgal_orient_k << ", MST)";
  if (scale_regions > 0) s << ", scale_regions=" << scale_regions;
  if (k_h > 0) s << ", K_h=" << k_h;
  if (scale_gamma >= 0) s << ", scale_gamma=" << scale_gamma;
  if (passes > 0) s << ", passes=" << passes;
  if (normals_orient_only) s << ", normals_orient_only";
  s << (merge ? ", merge_eps=default (0.25 s)" : ", merge_eps=0");
  return s.str();
}

FilterRun run_robust_filter(const std::vector<Eigen::Vector3d>& input,
                            const FilterSettings& settings) {
  PointCloud cloud;
  cloud.positions = input;
  return run_robust_filter(cloud, settings);
}

#ifdef SCANCLEAN_BENCH_HAVE_FILTER

bool filter_available() {
  return true;
}

FilterRun run_robust_filter(const PointCloud& input, const FilterSettings& settings) {
  FilterOptions options;
  if (!settings.merge) options.merge_eps = 0;
  if (settings.adaptive) {
    options.scale = ScaleMode::kAdaptive;
    options.k_adaptive = settings.k_adaptive;
  }
  options.kernel_stride = settings.kernel_stride;
  options.threads = settings.threads;
  if (settings.refit_spread >= 0) options.refit_spread = settings.refit_spread;
  if (settings.crease_spread >= 0) options.crease_spread = settings.crease_spread;
  if (!settings.adaptive) options.scale_regions = settings.scale_regions;
  options.normals_orient_only = settings.normals_orient_only;
  options.orient_k = settings.orient_k;
  if (settings.k_h > 0) options.k_h = settings.k_h;
  if (settings.scale_gamma >= 0) options.scale_gamma = settings.scale_gamma;
  if (settings.passes > 0) options.passes = settings.passes;
  const auto t0 = std::chrono::steady_clock::now();
  FilterResult r;
  if (settings.cgal_orient_k > 0 && !input.has_normals()) {
#ifdef SCANCLEAN_BENCH_HAVE_MESH_SUITE
    PointCloud oriented = input;
    oriented.normals = estimate_orienting_normals(oriented, settings.cgal_orient_k);
    options.normals_orient_only = true;
    r = robust_filter(oriented, options);
#else
    throw UnavailableError("--orient-normals-cgal needs the mesh module (CGAL) in this build");
#endif
  } else {
    r = robust_filter(input, options);
  }
  const auto t1 = std::chrono::steady_clock::now();
  FilterRun run;
  run.seconds_wall = std::chrono::duration<double>(t1 - t0).count();
  run.kept.assign(input.size(), 0);
  run.input_to_output.assign(input.size(), -1);
  const Attribute* src = r.cloud.find_attribute("source_index");
  if (src == nullptr) throw std::logic_error("robust_filter output lacks source_index");
  if (settings.merge) {
    // With merging an output point stands for several inputs: every input not listed among the
    // outliers is represented.
    run.kept.assign(input.size(), 1);
    const Attribute* osrc = r.outliers.find_attribute("source_index");
    if (osrc == nullptr) throw std::logic_error("robust_filter outliers lack source_index");
    for (double v : osrc->values) run.kept[static_cast<std::size_t>(v)] = 0;
  } else {
    for (std::size_t o = 0; o < src->values.size(); ++o) {
      const auto i = static_cast<std::size_t>(src->values[o]);
      run.kept[i] = 1;
      run.input_to_output[i] = static_cast<std::int64_t>(o);
    }
  }
  const FilterStats& s = r.stats;
  run.h = s.h;
  run.noise_sigma = s.noise_sigma;
  run.mean_iterations = s.mean_iterations;
  run.kernels = s.kernels;
  run.kernels_refitted = s.kernels_refitted;
  run.kernels_split = s.kernels_split;
  run.p95_iterations = s.p95_iterations;
  run.unsupported = s.unsupported;
  run.off_surface = s.off_surface;
  run.low_density = s.low_density;
  run.low_likelihood = s.low_likelihood;
  run.displaced = s.displaced;
  run.small_components = s.small_components;
  run.merged = s.merged;
  run.not_converged = s.not_converged;
  run.s_scale = s.seconds_scale;
  run.s_kernels = s.seconds_kernels;
  run.s_projection = s.seconds_projection;
  run.s_clustering = s.seconds_clustering;
  run.s_outliers = s.seconds_outliers;
  run.s_total = s.seconds_total;
  run.cloud = std::move(r.cloud);
  return run;
}

#else

bool filter_available() {
  return false;
}

FilterRun run_robust_filter(const PointCloud&, const FilterSettings&) {
  throw UnavailableError("scanclean_bench was built without the filter module (robust_filter)");
}

#endif

}  // namespace scanclean::bench

// scanclean filter: the robust filter (Schall, Belyaev, Seidel 2005) on point-cloud files.
// Needs the io and filter modules; without either the subcommand is not built.

#if defined(SCANCLEAN_HAVE_IO) && defined(SCANCLEAN_HAVE_FILTER)

#include <CLI/CLI.hpp>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "scanclean/command.h"
#include "scanclean/core/errors.h"
#include "scanclean/core/progress.h"
#include "scanclean/filter/robust_filter.h"
#include "scanclean/io/point_cloud_io.h"
#include "scanclean/mesh_handoff.h"
#include "scanclean/summary.h"

namespace scanclean::app {
namespace {

struct FilterCommandOptions {
  std::vector<std::string> inputs;
  std::string output;
  std::string conf;
  std::string outliers;
  double h = 0;
  int k = 0;
  bool auto_scale = false;
  int k_h = FilterOptions{}.k_h;
  double noise_factor = FilterOptions{}.noise_factor;
  double scale_gamma = FilterOptions{}.scale_gamma;
  int kernel_stride = FilterOptions{}.kernel_stride;
  double likelihood_ratio = FilterOptions{}.likelihood_ratio;
  double displacement_sigma = FilterOptions{}.displacement_sigma;
  double outlier_sigma = FilterOptions{}.outlier_sigma;
  std::string update = "normal";
  double merge_eps = -1;
  double tau = FilterOptions{}.tau;
  int passes = 1;
  int threads = 0;
  int k_min = 8;
  int max_iterations = 20;
  long long small_components = -1;  // -1 off, 0 automatic size, > 0 size
  bool no_sensor_normals = false;
  bool no_confidences = false;
  bool ascii = false;
  bool skip_missing = false;
  std::shared_ptr<MeshHandoff> mesh;  // --mesh FILE
};

void print_warnings(const std::string& file, const ReadReport& report) {
  for (const auto& w : report.warnings) std::fprintf(stderr, "scanclean: warning: %s\n", w.c_str());
  if (report.dropped_invalid > 0)
    std::fprintf(stderr, "scanclean: %s: %zu invalid points dropped while reading\n", file.c_str(),
                 report.dropped_invalid);
}

int run_filter(const FilterCommandOptions& c) {
  if (c.inputs.empty() && c.conf.empty())
    throw OptionError("filter: give at least one input file or --conf FILE");
  check_mesh_output(*c.mesh, "filter");
  PointCloud cloud;
  std::size_t files = 0;
  for (const auto& in : c.inputs) {
    ReadReport report;
    PointCloud part = read_point_cloud(in, &report);
    print_warnings(in, report);
    append(cloud, part);
    ++files;
  }
  if (!c.conf.empty()) {
    ReadReport report;
    ConfOptions conf_options;
    conf_options.skip_missing = c.skip_missing;
    PointCloud part = read_and_merge_conf(c.conf, &report, conf_options);
    print_warnings(c.conf, report);
    append(cloud, part);
    ++files;
  }

  FilterOptions o;
  if (c.h > 0) {
    o.scale = ScaleMode::kFixed;
    o.h = c.h;
  } else if (c.k > 0) {
    o.scale = ScaleMode::kAdaptive;
    o.k_adaptive = c.k;
  } else {
    o.scale = ScaleMode::kAuto;
  }
  o.k_h = c.k_h;
  o.noise_factor = c.noise_factor;
  o.scale_gamma = c.scale_gamma;
  o.kernel_stride = c.kernel_stride;
  o.likelihood_ratio = c.likelihood_ratio;
  o.displacement_sigma = c.displacement_sigma;
  o.outlier_sigma = c.outlier_sigma;
  o.k_min = c.k_min;
  o.max_iterations = c.max_iterations;
  o.update = c.update == "vector" ? UpdateMode::kVector : UpdateMode::kNormal;
  o.merge_eps = c.merge_eps;
  o.tau = c.tau;
  o.passes = c.passes;
  o.threads = c.threads;
  o.use_sensor_normals = !c.no_sensor_normals;
  o.use_confidences = !c.no_confidences;
  if (c.small_components >= 0) {
    o.remove_small_components = true;
    o.min_component_size = static_cast<std::size_t>(c.small_components);
  }
  std::unique_ptr<Progress> bar;
  std::string phase;
  std::uint64_t done = 0;
  o.progress = [&](const std::string& p, double fraction) {
    if (p != phase) {
      bar.reset();  // finishes the previous bar
      bar = std::make_unique<Progress>("filter: " + p, 1000);
      phase = p;
      done = 0;
    }
    const auto target = static_cast<std::uint64_t>(fraction * 1000.0);
    if (target > done) {
      bar->advance(target - done);
      done = target;
    }
  };
  validate(o);  // before the (possibly long) run, so a bad option fails fast

  const FilterResult r = robust_filter(cloud, o);
  bar.reset();

  WriteOptions w;
  if (c.ascii) {
    w.ply_encoding = PlyEncoding::kAscii;
    w.pcd_encoding = "ascii";
  }
  write_point_cloud(c.output, r.cloud, w);
  if (!c.outliers.empty()) write_point_cloud(c.outliers, r.outliers, w);

  const FilterStats& s = r.stats;
  Summary sum("scanclean filter");
  sum.add("input", std::to_string(files) + (files == 1 ? " file" : " files"));
  sum.add_count("points in", s.points_in);
  sum.add_count("points out", s.points_out);
  sum.add_count("merged into others", s.merged);
  sum.add("outliers removed",
          with_thousands(s.removed()) + " (unsupported " + with_thousands(s.unsupported) +
              ", off surface " + with_thousands(s.off_surface) + ", low density " +
              with_thousands(s.low_density) + ", low likelihood " +
              with_thousands(s.low_likelihood) + ", displaced " + with_thousands(s.displaced) +
              ", small components " + with_thousands(s.small_components) + ")");
  if (!c.outliers.empty()) sum.add("outliers file", c.outliers);
  sum.add("output file", c.output);
  const char* mode = o.scale == ScaleMode::kFixed  ? "fixed"
                     : o.scale == ScaleMode::kAuto ? "auto"
                                                   : "adaptive";
  sum.add("scale", std::string(mode));
  sum.add("h", s.h * 1000.0, 3, "mm");
  if (o.scale == ScaleMode::kAdaptive) {
    char range[96];
    std::snprintf(range, sizeof range, "%.3f .. %.3f mm (median shown as h)", s.h_min * 1000.0,
                  s.h_max * 1000.0);
    sum.add("h range", range);
  }
  if (o.scale == ScaleMode::kAuto) {
    sum.add("noise sigma (estimate)", s.noise_sigma * 1000.0, 3, "mm");
    if (o.scale_gamma > 0) sum.add("h before the scale test", s.h_noise * 1000.0, 3, "mm");
  }
  sum.add("mean spacing", s.mean_spacing * 1000.0, 3, "mm");
  sum.add("kernels", with_thousands(s.kernels) +
                         (s.kernel_stride == 1
                              ? std::string(" (at every point)")
                              : " (at one point in " + std::to_string(s.kernel_stride) + ")"));
  sum.add("merge eps", s.merge_eps * 1000.0, 3, "mm");
  sum.add("iterations", std::to_string(s.mean_iterations).substr(0, 4) + " mean, " +
                            std::to_string(static_cast<int>(s.p95_iterations)) + " p95");
  sum.add_count("not converged", s.not_converged);
  char phases[256];
  std::snprintf(phases, sizeof phases,
                "scale %.2f, kernels %.2f, projection %.2f, clustering %.2f, outliers %.2f s",
                s.seconds_scale, s.seconds_kernels, s.seconds_projection, s.seconds_clustering,
                s.seconds_outliers);
  sum.add("time", phases);
  sum.add("total", s.seconds_total, 2, "s");
  sum.add_count("points per second", static_cast<unsigned long long>(
                                         s.seconds_total > 0 ? s.points_in / s.seconds_total : 0));
  sum.add("threads", std::to_string(s.threads));
  sum.add("peak memory", static_cast<double>(s.peak_rss_bytes) / 1048576.0, 1, "MiB");
  run_mesh_handoff(*c.mesh, r.cloud, s.h, sum);
  sum.print();
  return 0;
}

const CommandRegistrar kRegistrar{{
    "filter",
    "Robust filter: denoise a point cloud and remove outliers (Schall et al. 2005)",
    30,
    [](CLI::App& cmd) {
      auto c = std::make_shared<FilterCommandOptions>();
      cmd.add_option("inputs", c->inputs,
                     "Input point clouds (.ply .pcd .xyz .txt, metres); several are merged");
      cmd.add_option("-o,--output", c->output, "Output point cloud (format by extension)")
          ->required();
      cmd.add_option("--conf", c->conf,
                     "Stanford .conf scan session: every scan transformed and merged (added to "
                     "the inputs)");
      cmd.add_flag("--skip-missing", c->skip_missing,
                   "With --conf: merge the scans that exist, warn about missing ones (default: "
                   "a missing scan is an error)");
      auto* h = cmd.add_option("--h", c->h,
                               "Fixed kernel size h in metres (the paper uses 1-10x the mean "
                               "point spacing)")
                    ->check(positive_number());
      auto* k = cmd.add_option("--k", c->k,
                               "Adaptive kernels: h_i = distance to the k-th nearest neighbour "
                               "(the paper uses 250 on raw overlapping scans)")
                    ->check(CLI::Range(2, 1000));
      auto* a = cmd.add_flag("--auto", c->auto_scale,
                             "Automatic h (default): median distance to the K_h-th neighbour, "
                             "raised to --noise-factor x the noise sigma estimated at that scale, "
                             "then adjusted by the scale test (--scale-gamma)");
      h->excludes(k)->excludes(a);
      k->excludes(a);
      cmd.add_option("--k-h", c->k_h, "K_h, the neighbour rank of the automatic h")
          ->capture_default_str();
      cmd.add_option("--noise-factor", c->noise_factor,
                     "Automatic h: at least this many times the noise sigma (estimated at the "
                     "scale h itself; the spec's literal rule is 3 at h0)")
          ->capture_default_str();
      cmd.add_option("--scale-gamma", c->scale_gamma,
                     "Automatic h, last step: the median, over sampled points, of the largest "
                     "ball (0.5 to 1.41 x the noise rule's h) whose plane agrees with every "
                     "smaller ball's within this many standard errors; larger h on smooth "
                     "surfaces, smaller on curved or thin parts (0 = off)")
          ->check(CLI::Range(0.0, 20.0))
          ->capture_default_str();
      cmd.add_option("--kernel-stride", c->kernel_stride,
                     "Kernels at every N-th point (weights x N); 1 = at every point, as the "
                     "paper; 0 = automatic: 1 unless h was raised above h0 (noise, scale test), "
                     "then (h/h0)^2")
          ->capture_default_str();
      cmd.add_option("--update", c->update,
                     "Projection step: 'normal' moves along the mean normal (default), "
                     "'vector' is the paper's literal x <- x - m")
          ->check(CLI::IsMember({"normal", "vector"}))
          ->default_val("normal");
      cmd.add_option("--merge-eps", c->merge_eps,
                     "Merge converged points closer than this (metres); 0 = keep every point; "
                     "default 0.25 x mean spacing");
      cmd.add_option("--tau", c->tau,
                     "Drop points whose density is below tau x the median density (0 = off)")
          ->capture_default_str();
      cmd.add_option("--outlier-sigma", c->outlier_sigma,
                     "Before projecting, drop points farther than this many standard deviations "
                     "from every kernel around them, each kernel refitted without the point and "
                     "its own centre (catches outliers closer than h; 0 = off)")
          ->capture_default_str();
      cmd.add_option("--likelihood-ratio", c->likelihood_ratio,
                     "Drop points whose likelihood is below this fraction of the lower "
                     "quartile of the likelihoods of the points within h (points stopped off "
                     "the surface; 0 = off)")
          ->capture_default_str();
      cmd.add_option("--displacement-sigma", c->displacement_sigma,
                     "After projecting, drop points whose move along the normal differs from "
                     "the median move of the points within h by more than this many robust "
                     "standard deviations (outliers pulled onto the surface; 0 = off)")
          ->capture_default_str();
      cmd.add_option("--small-components", c->small_components,
                     "Also drop connected pieces (link radius h) with fewer input points than "
                     "this; 0 = max(k_min, 0.1 % of the points)");
      cmd.add_option("--outliers", c->outliers,
                     "Write the removed input points here (attribute flags: 1 unsupported, 2 "
                     "outlier)");
      cmd.add_option("--passes", c->passes,
                     "2 = rebuild the kernels from the first result and project again (heavy "
                     "noise)")
          ->default_val(1);
      cmd.add_option("--k-min", c->k_min, "Points with fewer neighbours within h get no kernel")
          ->default_val(8);
      cmd.add_option("--max-iterations", c->max_iterations, "Iteration cap per point")
          ->default_val(20);
      cmd.add_flag("--no-sensor-normals", c->no_sensor_normals,
                   "Ignore input normals (default: they replace the PCA normals and keep the "
                   "two sides of thin parts apart)");
      cmd.add_flag("--no-confidences", c->no_confidences,
                   "Ignore input confidences (default: they weight the kernels)");
      cmd.add_option("--threads", c->threads,
                     "Worker threads, 0 = all cores (the result is identical for any value)")
          ->default_val(0);
      cmd.add_flag("--ascii", c->ascii, "Write ASCII PLY/PCD instead of binary");
      c->mesh = add_mesh_option(cmd);
      return [c] { return run_filter(*c); };
    },
}};

}  // namespace
}  // namespace scanclean::app

#endif  // SCANCLEAN_HAVE_IO && SCANCLEAN_HAVE_FILTER

#if defined(SCANCLEAN_HAVE_FILTER)

#include "scanclean/filter_options_cli.h"

#include "scanclean/command.h"

namespace scanclean::app {

std::shared_ptr<FilterCliValues> add_filter_options(CLI::App& cmd, const FilterCliValues& defaults,
                                                    bool with_threads) {
  auto v = std::make_shared<FilterCliValues>(defaults);
  auto* h = cmd.add_option("--h", v->h,
                           "Fixed kernel size h in metres (the paper uses 1-10x the mean point "
                           "spacing); default automatic")
                ->check(positive_number());
  auto* k = cmd.add_option("--k", v->k,
                           "Adaptive kernels: h_i = distance to the k-th nearest neighbour (the "
                           "paper uses 250 on raw overlapping scans)")
                ->check(integer_in(2, 1000));
  auto* a = cmd.add_flag("--auto", v->auto_scale,
                         "Automatic h (default): median distance to the K_h-th neighbour, "
                         "raised to --noise-factor x the noise sigma estimated at that scale, "
                         "then adjusted by the scale test (--scale-gamma)");
  h->excludes(k)->excludes(a);
  k->excludes(a);
  cmd.add_option("--k-h", v->k_h, "K_h, the neighbour rank of the automatic h")
      ->check(integer_in(2, 1000))
      ->capture_default_str();
  cmd.add_option("--noise-factor", v->noise_factor,
                 "Automatic h: at least this many times the noise sigma (estimated at the "
                 "scale h itself; the spec's literal rule is 3 at h0)")
      ->check(number_in(0, 20, true))
      ->capture_default_str();
  cmd.add_option("--scale-gamma", v->scale_gamma,
                 "Automatic h, last step: the median, over sampled points, of the largest ball "
                 "(0.5 to 1.41 x the noise rule's h) whose plane agrees with every smaller "
                 "ball's within this many standard errors; larger h on smooth surfaces, smaller "
                 "on curved or thin parts (0 = off; off by default on depth frames, where it "
                 "reads the depth steps as structure)")
      ->check(number_in(0, 20))
      ->capture_default_str();
  cmd.add_option("--scale-regions", v->scale_regions,
                 "Automatic h with the scale test: a scale per region, each point's h the median "
                 "of the scale test's radii at the K sampled points nearest to its grid cell (of "
                 "about 2,500; 96 suits the benchmark's thin parts, creases and fine detail), "
                 "instead of one median for the cloud (0 = off); with --crease-spread, the "
                 "points beside a sharp crease keep the h of their own face; not in tiled runs")
      ->check(CLI::Range(0, 256))
      ->capture_default_str();
  cmd.add_option("--kernel-stride", v->kernel_stride,
                 "Kernels at every N-th point (weights x N); 1 = at every point, as the paper; "
                 "0 = automatic: 1 unless h was raised above h0 (noise, scale test), then "
                 "(h/h0)^2")
      ->check(integer_in(0, 64))
      ->capture_default_str();
  cmd.add_option("--update", v->update,
                 "Projection step: 'normal' moves along the mean normal (default), 'vector' is "
                 "the paper's literal x <- x - m")
      ->check(CLI::IsMember({"normal", "vector"}))
      ->capture_default_str();
  cmd.add_option("--merge-eps", v->merge_eps,
                 "Merge converged points closer than this (metres, >= 0); 0 = keep every point; "
                 "default (not given) 0.25 x mean spacing")
      ->check(non_negative_number());
  cmd.add_option("--tau", v->tau,
                 "Drop points whose density is below tau x the median density (0 = off)")
      ->check(number_in(0, 1))
      ->capture_default_str();
  cmd.add_option("--crease-spread", v->crease_spread,
                 "Crease split: fit a kernel on its own face where two flat faces meet in a "
                 "sharp edge within h (tested where its plane leaves more than this many noise "
                 "sigma as spread), so edges stay sharp; automatic h, also tiled; 0 = off; 1.1 "
                 "suits CAD parts and other sharp objects")
      ->check(number_in(0, 100))
      ->capture_default_str();
  cmd.add_option("--refit-spread", v->refit_spread,
                 "Sheet refit: fit a kernel on its own sheet where two sheets lie within h "
                 "(tested where its plane leaves more than this many noise sigma as spread), so "
                 "thin parts stay apart; not in clouds with sensor normals (they keep the "
                 "sheets apart), automatic h, also tiled; 0 = off; 1.1 suits thin parts and "
                 "detail finer than h")
      ->check(number_in(0, 100))
      ->capture_default_str();
  cmd.add_option("--outlier-sigma", v->outlier_sigma,
                 "Before projecting, drop points farther than this many standard deviations "
                 "from every kernel around them, each kernel refitted without the point and its "
                 "own centre (catches outliers closer than h; 0 = off)")
      ->check(number_in(0, 100))
      ->capture_default_str();
  cmd.add_option("--likelihood-ratio", v->likelihood_ratio,
                 "Drop points whose likelihood is below this fraction of the lower quartile of "
                 "the likelihoods of the points within h (points stopped off the surface; 0 = "
                 "off)")
      ->check(number_in(0, 1))
      ->capture_default_str();
  cmd.add_option("--displacement-sigma", v->displacement_sigma,
                 "After projecting, drop points whose move along the normal differs from the "
                 "median move of the points within h by more than this many robust standard "
                 "deviations (outliers pulled onto the surface; 0 = off; off by default on "
                 "depth frames, where it takes surface points within the sensor noise)")
      ->check(number_in(0, 100))
      ->capture_default_str();
  cmd.add_option("--small-components", v->small_components,
                 "Also drop connected pieces (link radius h) with fewer input points than this "
                 "(>= 0); 0 = max(k_min, 0.1 % of the points); default off")
      ->check(non_negative_number());
  cmd.add_option("--passes", v->passes,
                 "2 = rebuild the kernels from the first result and project again: a second "
                 "smoothing for large noisy clouds (merged scans: closer to the surface at about "
                 "1.55x the time), which rounds fine detail and small clouds further")
      ->check(integer_in(1, 2))
      ->capture_default_str();
  cmd.add_option("--k-min", v->k_min, "Points with fewer neighbours within h get no kernel")
      ->check(integer_in(3, 1000))
      ->capture_default_str();
  cmd.add_option("--max-iterations", v->max_iterations, "Iteration cap per point")
      ->check(integer_in(1, 255))
      ->capture_default_str();
  cmd.add_flag("--no-sensor-normals", v->no_sensor_normals,
               "Ignore input (sensor) normals and estimate them by PCA (default: they replace "
               "the PCA normals and keep the two sides of thin parts apart)");
  cmd.add_flag("--no-confidences", v->no_confidences,
               "Ignore input confidences (default: they weight the kernels)");
  if (with_threads)
    cmd.add_option("--threads", v->threads,
                   "Worker threads, 0 = all cores (the result is identical for any value)")
        ->check(integer_in(0, 1024))
        ->capture_default_str();
  return v;
}

FilterCliValues values_of(const FilterOptions& o) {
  FilterCliValues v;
  v.k_h = o.k_h;
  v.noise_factor = o.noise_factor;
  v.scale_gamma = o.scale_gamma;
  v.scale_regions = o.scale_regions;
  v.kernel_stride = o.kernel_stride;
  v.likelihood_ratio = o.likelihood_ratio;
  v.displacement_sigma = o.displacement_sigma;
  v.outlier_sigma = o.outlier_sigma;
  v.refit_spread = o.refit_spread;
  v.crease_spread = o.crease_spread;
  v.tau = o.tau;
  v.passes = o.passes;
  v.k_min = o.k_min;
  v.max_iterations = o.max_iterations;
  return v;
}

FilterOptions to_filter_options(const FilterCliValues& c) {
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
  o.scale_regions = c.scale_regions;
  o.kernel_stride = c.kernel_stride;
  o.likelihood_ratio = c.likelihood_ratio;
  o.displacement_sigma = c.displacement_sigma;
  o.outlier_sigma = c.outlier_sigma;
  o.refit_spread = c.refit_spread;
  o.crease_spread = c.crease_spread;
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
  return o;
}

const char* scale_mode_name(ScaleMode mode) {
  return mode == ScaleMode::kFixed ? "fixed" : mode == ScaleMode::kAuto ? "auto" : "adaptive";
}

FilterProgress::FilterProgress(FilterOptions& options) {
  options.progress = [this](const std::string& p, double fraction) { report(p, fraction); };
}

void FilterProgress::report(const std::string& phase, double fraction) {
  if (phase != phase_ || !bar_) {
    bar_.reset();  // finishes the previous bar
    bar_ = std::make_unique<Progress>("filter: " + phase, 1000);
    phase_ = phase;
    done_ = 0;
  }
  const auto target = static_cast<std::uint64_t>(fraction * 1000.0);
  if (target > done_) {
    bar_->advance(target - done_);
    done_ = target;
  }
}

}  // namespace scanclean::app

#endif  // SCANCLEAN_HAVE_FILTER

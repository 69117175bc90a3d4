#pragma once
//! The command-line mapping of the robust filter's options, written once for every command that
//! runs the filter (filter, replay, capture, sl decode): the option names, their help, their
//! range checks (messages name the option as typed, e.g. "--k-h: expected an integer in [2,
//! 1000], got 1") and the translation into FilterOptions. Also the filter's progress bar.

#include <CLI/CLI.hpp>
#include <cstdint>
#include <memory>
#include <string>

#include "scanclean/core/progress.h"
#include "scanclean/filter/robust_filter.h"

namespace scanclean::app {

//! The filter options as typed. Defaults are FilterOptions' unless a command changes them.
struct FilterCliValues {
  double h = 0;  //!< > 0: fixed scale
  int k = 0;     //!< > 0: adaptive scale
  bool auto_scale = false;
  int k_h = FilterOptions{}.k_h;
  double noise_factor = FilterOptions{}.noise_factor;
  double scale_gamma = FilterOptions{}.scale_gamma;
  int scale_regions = FilterOptions{}.scale_regions;
  int kernel_stride = FilterOptions{}.kernel_stride;
  double likelihood_ratio = FilterOptions{}.likelihood_ratio;
  double displacement_sigma = FilterOptions{}.displacement_sigma;
  double outlier_sigma = FilterOptions{}.outlier_sigma;
  double refit_spread = FilterOptions{}.refit_spread;
  double crease_spread = FilterOptions{}.crease_spread;
  std::string update = "normal";
  double merge_eps = -1;  //!< -1 = not given (automatic); the option itself refuses < 0
  double tau = FilterOptions{}.tau;
  int passes = FilterOptions{}.passes;
  int threads = 0;
  int k_min = FilterOptions{}.k_min;
  int max_iterations = FilterOptions{}.max_iterations;
  long long small_components = -1;  //!< -1 = off (not given), 0 automatic size, > 0 size
  bool no_sensor_normals = false;
  bool no_confidences = false;
};

//! Adds every filter option to `cmd` (with `defaults` shown in --help) and returns the values
//! CLI11 fills in. `--threads` is left out when `with_threads` is false (a command that has its
//! own, e.g. sl decode).
std::shared_ptr<FilterCliValues> add_filter_options(CLI::App& cmd,
                                                    const FilterCliValues& defaults = {},
                                                    bool with_threads = true);

//! The values that stand for the library's options `o`: what a command shows and starts from
//! when it uses one of the library's presets (e.g. values_of(depth_frame_options())), so that
//! defaults are decided once, in the library.
FilterCliValues values_of(const FilterOptions& o);

//! The FilterOptions for these values (not validated; the CLI checks already ran).
FilterOptions to_filter_options(const FilterCliValues& values);

//! "fixed", "auto" or "adaptive".
const char* scale_mode_name(ScaleMode mode);

//! A progress bar per filter phase ("filter: scale", "filter: projection", ...). Attach it to
//! the options before robust_filter(); finish() (or the destructor) closes the last bar.
class FilterProgress {
 public:
  explicit FilterProgress(FilterOptions& options);
  ~FilterProgress() { finish(); }
  FilterProgress(const FilterProgress&) = delete;
  FilterProgress& operator=(const FilterProgress&) = delete;
  void finish() { bar_.reset(); }

 private:
  void report(const std::string& phase, double fraction);
  std::unique_ptr<Progress> bar_;
  std::string phase_;
  std::uint64_t done_ = 0;
};

}  // namespace scanclean::app

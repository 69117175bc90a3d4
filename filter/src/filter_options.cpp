#include "scanclean/filter/filter_options.h"

#include <cmath>
#include <sstream>
#include <string>

#include "scanclean/core/errors.h"

namespace scanclean {
namespace {

template <class T>
std::string to_str(const T& v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

[[noreturn]] void bad_option(const std::string& name, const std::string& value,
                             const std::string& range) {
  throw OptionError("filter option " + name + " = " + value + " is invalid: expected " + range);
}

void check_int(const std::string& name, long long v, long long lo, long long hi) {
  if (v < lo || v > hi)
    bad_option(name, to_str(v), "an integer in [" + to_str(lo) + ", " + to_str(hi) + "]");
}

// lo_open: (lo, hi]; otherwise [lo, hi].
void check_real(const std::string& name, double v, double lo, double hi, bool lo_open) {
  const bool ok = std::isfinite(v) && (lo_open ? v > lo : v >= lo) && v <= hi;
  if (!ok)
    bad_option(
        name, to_str(v),
        std::string("a number in ") + (lo_open ? "(" : "[") + to_str(lo) + ", " + to_str(hi) + "]");
}

}  // namespace

void validate(const FilterOptions& o) {
  if (o.scale == ScaleMode::kFixed) {
    if (!(std::isfinite(o.h) && o.h > 0))
      bad_option("h", to_str(o.h), "a kernel size > 0 metres with the fixed scale");
  } else if (!(std::isfinite(o.h) && o.h >= 0)) {
    bad_option("h", to_str(o.h), "0 (unused) or a size > 0 metres");
  }
  if (o.scale != ScaleMode::kAuto && o.scale != ScaleMode::kFixed &&
      o.scale != ScaleMode::kAdaptive)
    bad_option("scale", to_str(static_cast<int>(o.scale)), "auto, fixed or adaptive");
  if (o.update != UpdateMode::kNormal && o.update != UpdateMode::kVector)
    bad_option("update", to_str(static_cast<int>(o.update)), "normal or vector");
  check_int("k_h", o.k_h, 2, 1000);
  check_int("k_adaptive", o.k_adaptive, 2, 1000);
  check_int("k_min", o.k_min, 3, 1000);
  check_real("truncation_sigma", o.truncation_sigma, 0, 10, true);
  check_real("noise_factor", o.noise_factor, 0, 20, true);
  check_real("scale_gamma", o.scale_gamma, 0, 20, false);
  check_int("scale_regions", o.scale_regions, 0, 256);
  if (o.scale_regions > 0 && (o.scale != ScaleMode::kAuto || !(o.scale_gamma > 0)))
    bad_option("scale_regions", to_str(o.scale_regions),
               "0 unless the scale is automatic with the scale test on (scale_gamma > 0)");
  if (o.orient_k != 0) check_int("orient_k", o.orient_k, kMinOrientK, kMaxOrientK);
  if (o.orient_viewpoint) {
    const auto& v = *o.orient_viewpoint;
    if (!(std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2])))
      bad_option("orient_viewpoint", to_str(v[0]) + ", " + to_str(v[1]) + ", " + to_str(v[2]),
                 "three finite coordinates (metres)");
    if (o.orient_k == 0)
      bad_option("orient_viewpoint", "set", "only with orient_k (the normals it orients)");
  }
  check_int("kernel_stride", o.kernel_stride, 0, 64);
  check_real("slab", o.slab, 0, 10, true);
  check_real("eigen_floor", o.eigen_floor, 0, 1, true);
  check_real("tolerance", o.tolerance, 0, 0.1, true);
  check_int("max_iterations", o.max_iterations, 1, 255);
  check_int("passes", o.passes, 1, 2);
  if (!std::isfinite(o.merge_eps))
    bad_option("merge_eps", to_str(o.merge_eps),
               "a finite number (< 0: default 0.25 x mean spacing, 0: off, > 0: metres)");
  check_real("tau", o.tau, 0, 1, false);
  check_real("likelihood_ratio", o.likelihood_ratio, 0, 1, false);
  check_real("displacement_sigma", o.displacement_sigma, 0, 100, false);
  check_real("outlier_sigma", o.outlier_sigma, 0, 100, false);
  check_real("refit_spread", o.refit_spread, 0, 100, false);
  check_real("crease_spread", o.crease_spread, 0, 100, false);
  check_real("refit_noise_sigma", o.refit_noise_sigma, 0, 1e6, false);
  if (o.min_component_size > 1000000000ULL)
    bad_option("min_component_size", to_str(o.min_component_size),
               "0 (automatic) or a point count <= 1e9");
  check_int("threads", o.threads, 0, 1024);
}

FilterOptions depth_frame_options() {
  FilterOptions o;
  o.scale_gamma = 0;
  o.displacement_sigma = 0;
  o.refit_spread = 0;
  o.crease_spread = 0;
  return o;
}

}  // namespace scanclean

#include "filter_binding.h"

#include <pybind11/functional.h>
#include <pybind11/stl.h>

#include <array>
#include <string>
#include <vector>

#include "cloud_arrays.h"
#include "scanclean/core/errors.h"
#include "scanclean/filter/robust_filter.h"

namespace py = pybind11;

namespace scanclean::python {
namespace {

const char* scale_name(ScaleMode s) {
  switch (s) {
    case ScaleMode::kFixed:
      return "fixed";
    case ScaleMode::kAdaptive:
      return "adaptive";
    case ScaleMode::kAuto:
      break;
  }
  return "auto";
}

//! Every FilterOptions field by its C++ name, except progress (a keyword of its own).
py::dict options_to_dict(const FilterOptions& o) {
  py::dict d;
  d["scale"] = scale_name(o.scale);
  d["h"] = o.h;
  d["k_h"] = o.k_h;
  d["noise_factor"] = o.noise_factor;
  d["scale_gamma"] = o.scale_gamma;
  d["scale_regions"] = o.scale_regions;
  d["kernel_stride"] = o.kernel_stride;
  d["k_adaptive"] = o.k_adaptive;
  d["k_min"] = o.k_min;
  d["truncation_sigma"] = o.truncation_sigma;
  d["slab"] = o.slab;
  d["eigen_floor"] = o.eigen_floor;
  d["tolerance"] = o.tolerance;
  d["max_iterations"] = o.max_iterations;
  d["update"] = o.update == UpdateMode::kVector ? "vector" : "normal";
  d["passes"] = o.passes;
  d["merge_eps"] = o.merge_eps;
  d["tau"] = o.tau;
  d["likelihood_ratio"] = o.likelihood_ratio;
  d["displacement_sigma"] = o.displacement_sigma;
  d["outlier_sigma"] = o.outlier_sigma;
  d["refit_spread"] = o.refit_spread;
  d["crease_spread"] = o.crease_spread;
  d["refit_noise_sigma"] = o.refit_noise_sigma;
  d["remove_small_components"] = o.remove_small_components;
  d["min_component_size"] = o.min_component_size;
  d["use_sensor_normals"] = o.use_sensor_normals;
  d["normals_orient_only"] = o.normals_orient_only;
  d["orient_k"] = o.orient_k;
  if (o.orient_viewpoint)
    d["orient_viewpoint"] = py::make_tuple((*o.orient_viewpoint)[0], (*o.orient_viewpoint)[1],
                                           (*o.orient_viewpoint)[2]);
  else
    d["orient_viewpoint"] = py::none();
  d["use_confidences"] = o.use_confidences;
  d["threads"] = o.threads;
  return d;
}

template <class T>
T as(const py::handle& value, const std::string& key) {
  try {
    return value.cast<T>();
  } catch (const py::cast_error&) {
    throw OptionError(key + ": expected " +
                      (std::is_same_v<T, bool>       ? "a bool"
                       : std::is_integral_v<T>       ? "an integer"
                       : std::is_floating_point_v<T> ? "a number"
                                                     : "a string") +
                      ", got " + std::string(py::repr(value)));
  }
}

//! FilterOptions from keyword arguments named like the fields. `h` without `scale` selects
//! "fixed" and `k_adaptive` without `scale` selects "adaptive", as the program's --h and --k do.
FilterOptions options_from_kwargs(const py::kwargs& kw) {
  FilterOptions o;
  bool scale_given = false;
  for (const auto& [key_handle, v] : kw) {
    const std::string k = py::str(key_handle);
    if (k == "scale") {
      const auto s = as<std::string>(v, k);
      if (s == "auto")
        o.scale = ScaleMode::kAuto;
      else if (s == "fixed")
        o.scale = ScaleMode::kFixed;
      else if (s == "adaptive")
        o.scale = ScaleMode::kAdaptive;
      else
        throw OptionError("scale: expected \"auto\", \"fixed\" or \"adaptive\", got \"" + s + "\"");
      scale_given = true;
    } else if (k == "update") {
      const auto s = as<std::string>(v, k);
      if (s == "normal")
        o.update = UpdateMode::kNormal;
      else if (s == "vector")
        o.update = UpdateMode::kVector;
      else
        throw OptionError("update: expected \"normal\" or \"vector\", got \"" + s + "\"");
    } else if (k == "h")
      o.h = as<double>(v, k);
    else if (k == "k_h")
      o.k_h = as<int>(v, k);
    else if (k == "noise_factor")
      o.noise_factor = as<double>(v, k);
    else if (k == "scale_gamma")
      o.scale_gamma = as<double>(v, k);
    else if (k == "scale_regions")
      o.scale_regions = as<int>(v, k);
    else if (k == "kernel_stride")
      o.kernel_stride = as<int>(v, k);
    else if (k == "k_adaptive")
      o.k_adaptive = as<int>(v, k);
    else if (k == "k_min")
      o.k_min = as<int>(v, k);
    else if (k == "truncation_sigma")
      o.truncation_sigma = as<double>(v, k);
    else if (k == "slab")
      o.slab = as<double>(v, k);
    else if (k == "eigen_floor")
      o.eigen_floor = as<double>(v, k);
    else if (k == "tolerance")
      o.tolerance = as<double>(v, k);
    else if (k == "max_iterations")
      o.max_iterations = as<int>(v, k);
    else if (k == "passes")
      o.passes = as<int>(v, k);
    else if (k == "merge_eps")
      o.merge_eps = as<double>(v, k);
    else if (k == "tau")
      o.tau = as<double>(v, k);
    else if (k == "likelihood_ratio")
      o.likelihood_ratio = as<double>(v, k);
    else if (k == "displacement_sigma")
      o.displacement_sigma = as<double>(v, k);
    else if (k == "outlier_sigma")
      o.outlier_sigma = as<double>(v, k);
    else if (k == "refit_spread")
      o.refit_spread = as<double>(v, k);
    else if (k == "crease_spread")
      o.crease_spread = as<double>(v, k);
    else if (k == "refit_noise_sigma")
      o.refit_noise_sigma = as<double>(v, k);
    else if (k == "remove_small_components")
      o.remove_small_components = as<bool>(v, k);
    else if (k == "min_component_size")
      o.min_component_size = as<std::size_t>(v, k);
    else if (k == "use_sensor_normals")
      o.use_sensor_normals = as<bool>(v, k);
    else if (k == "normals_orient_only")
      o.normals_orient_only = as<bool>(v, k);
    else if (k == "orient_k")
      o.orient_k = as<int>(v, k);
    else if (k == "orient_viewpoint") {
      if (v.is_none()) {
        o.orient_viewpoint.reset();
      } else {
        std::vector<double> xyz;
        try {
          xyz = v.cast<std::vector<double>>();
        } catch (const py::cast_error&) {
        }
        if (xyz.size() != 3)
          throw OptionError("orient_viewpoint: expected None or three numbers (x, y, z), got " +
                            std::string(py::repr(v)));
        o.orient_viewpoint = std::array<double, 3>{xyz[0], xyz[1], xyz[2]};
      }
    } else if (k == "use_confidences")
      o.use_confidences = as<bool>(v, k);
    else if (k == "threads")
      o.threads = as<int>(v, k);
    else {
      std::string known;
      for (const auto& [name, value] : options_to_dict(FilterOptions{}))
        known += (known.empty() ? "" : ", ") + std::string(py::str(name));
      throw OptionError("robust_filter: unknown option \"" + k + "\"; options: " + known +
                        ", progress");
    }
  }
  if (!scale_given && kw.contains("h")) o.scale = ScaleMode::kFixed;
  if (!scale_given && !kw.contains("h") && kw.contains("k_adaptive"))
    o.scale = ScaleMode::kAdaptive;
  return o;
}

py::dict stats_to_dict(const FilterStats& s) {
  py::dict d;
  d["points_in"] = s.points_in;
  d["points_out"] = s.points_out;
  d["removed"] = s.removed();
  d["unsupported"] = s.unsupported;
  d["low_density"] = s.low_density;
  d["off_surface"] = s.off_surface;
  d["low_likelihood"] = s.low_likelihood;
  d["displaced"] = s.displaced;
  d["small_components"] = s.small_components;
  d["merged"] = s.merged;
  d["kernels"] = s.kernels;
  d["kernels_refitted"] = s.kernels_refitted;
  d["kernels_split"] = s.kernels_split;
  d["h"] = s.h;
  d["h_min"] = s.h_min;
  d["h_max"] = s.h_max;
  d["h0"] = s.h0;
  d["mean_spacing"] = s.mean_spacing;
  d["noise_sigma"] = s.noise_sigma;
  d["noise_sigma_h0"] = s.noise_sigma_h0;
  d["h_noise"] = s.h_noise;
  d["scale_crease_samples"] = s.scale_crease_samples;
  d["kernel_stride"] = s.kernel_stride;
  d["merge_eps"] = s.merge_eps;
  d["mean_iterations"] = s.mean_iterations;
  d["p95_iterations"] = s.p95_iterations;
  d["not_converged"] = s.not_converged;
  d["seconds_scale"] = s.seconds_scale;
  d["seconds_kernels"] = s.seconds_kernels;
  d["seconds_projection"] = s.seconds_projection;
  d["seconds_clustering"] = s.seconds_clustering;
  d["seconds_outliers"] = s.seconds_outliers;
  d["orientation_trees"] = s.orientation_trees;
  d["seconds_orientation"] = s.seconds_orientation;
  d["seconds_total"] = s.seconds_total;
  d["peak_rss_bytes"] = s.peak_rss_bytes;
  d["threads"] = s.threads;
  return d;
}

py::dict run(const py::handle& points, const py::object& normals, const py::object& weights,
             const py::object& progress, const py::kwargs& kw) {
  PointCloud input = cloud_from_object(points);
  if (!normals.is_none()) input.normals = normals_from_array(normals, input.size(), "normals");
  if (!weights.is_none()) input.confidences = floats_from_array(weights, input.size(), "weights");
  FilterOptions o = options_from_kwargs(kw);
  if (!progress.is_none()) {
    // Called from the thread that called robust_filter(), which holds no GIL while it runs.
    o.progress = [progress](const std::string& phase, double fraction) {
      py::gil_scoped_acquire acquire;
      progress(phase, fraction);
    };
  }
  validate(o);
  FilterResult r;
  {
    py::gil_scoped_release release;
    r = robust_filter(input, o);
  }
  py::dict out = cloud_to_dict(r.cloud);
  out["outliers"] = cloud_to_dict(r.outliers);
  out["stats"] = stats_to_dict(r.stats);
  return out;
}

}  // namespace

void bind_filter(py::module_& m) {
  m.def("robust_filter", &run, py::arg("points"), py::arg("normals") = py::none(),
        py::arg("weights") = py::none(), py::kw_only(), py::arg("progress") = py::none(),
        R"doc(Robust filter (Schall, Belyaev, Seidel 2005; docs/ALGORITHM.md), the same code as
`scanclean filter`.

points: (N, 3) array in metres, or a dict as read() returns (every array it holds is used:
normals, confidences as weights, colours, intensities, attributes). normals: (N, 3) sensor
normals (zero rows = unknown); weights: (N,) confidences in [0, 1]. Options: keyword arguments
named like the fields of scanclean::FilterOptions (see default_filter_options()); h= without
scale= selects scale="fixed" and k_adaptive= selects "adaptive", like the program's --h / --k.
progress: optional callable(phase: str, fraction: float).

Returns a dict: points, normals, likelihood, iterations, flags, merge_count, source_index,
displacement (metres moved along the normal; and
the input's colours, intensities, confidences), "outliers" (the dropped input points with
flags and source_index) and "stats" (FilterStats as a dict).)doc");
  m.def(
      "default_filter_options", [] { return options_to_dict(FilterOptions{}); },
      "Every option robust_filter() accepts, with its default value.");
}

}  // namespace scanclean::python

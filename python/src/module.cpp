// The scanclean Python module: clouds in and out (numpy), the robust filter, range sources.
// Built with Debian's pybind11; every call goes through the same library code as the program.

#include <pybind11/pybind11.h>

#include "cloud_arrays.h"
#include "filter_binding.h"
#include "scanclean/core/errors.h"
#include "source_binding.h"

#ifndef SCANCLEAN_VERSION
#error "SCANCLEAN_VERSION must be defined by the build"
#endif

namespace py = pybind11;

PYBIND11_MODULE(scanclean, m) {
  m.doc() =
      "scanclean: robust filtering of noisy scanner output (Schall, Belyaev, Seidel 2005). "
      "read()/write() clouds as dicts of numpy arrays, robust_filter() on arrays, open_source() "
      "to iterate the frames of sensors, .oni files, recordings and depth images.";
  m.attr("__version__") = SCANCLEAN_VERSION;
  // The project's typed errors (core/errors.h), most derived last so that they are tried first.
  auto& error = py::register_exception<scanclean::Error>(m, "Error", PyExc_RuntimeError);
  py::register_exception<scanclean::InputError>(m, "InputError", error.ptr());
  py::register_exception<scanclean::OptionError>(m, "OptionError", error.ptr());
  py::register_exception<scanclean::IoError>(m, "IoError", error.ptr());
  py::register_exception<scanclean::UnavailableError>(m, "UnavailableError", error.ptr());
  scanclean::python::bind_cloud_io(m);
  scanclean::python::bind_filter(m);
  scanclean::python::bind_sources(m);
}

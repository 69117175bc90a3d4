#include "source_binding.h"

#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include <chrono>
#include <memory>
#include <string>

#include "scanclean/core/errors.h"
#include "scanclean/drivers/make_range_source.h"

namespace py = pybind11;

namespace scanclean::python {
namespace {

template <class T>
py::array_t<T> image_array(const Image<T>& img) {
  py::array_t<T> a({img.height, img.width});
  std::copy(img.data.begin(), img.data.end(), a.mutable_data());
  return a;
}

py::array_t<float> vector_image_array(const Image<Eigen::Vector3f>& img) {
  py::array_t<float> a({img.height, img.width, 3});
  float* out = a.mutable_data();
  for (std::size_t i = 0; i < img.data.size(); ++i)
    for (int k = 0; k < 3; ++k) out[3 * i + k] = img.data[i][k];
  return a;
}

py::dict intrinsics_dict(const Intrinsics& K) {
  py::dict d;
  d["fx"] = K.fx;
  d["fy"] = K.fy;
  d["cx"] = K.cx;
  d["cy"] = K.cy;
  d["width"] = K.width;
  d["height"] = K.height;
  d["dist"] = py::make_tuple(K.dist[0], K.dist[1], K.dist[2], K.dist[3], K.dist[4]);
  d["source"] = K.source;
  return d;
}

//! One frame, with its images copied into numpy arrays.
struct PyFrame {
  std::uint64_t index = 0;
  std::int64_t device_ts_us = 0;
  std::int64_t host_ts_ns = 0;
  double depth_unit_m = 0;
  py::array_t<std::uint16_t> depth;
  py::dict K;
  py::object points = py::none();
  py::object confidence = py::none();
  py::object sensor_normals = py::none();
};

PyFrame to_python(const RangeFrame& f) {
  PyFrame p;
  p.index = f.index;
  p.device_ts_us = f.device_ts_us;
  p.host_ts_ns = f.host_ts_ns;
  p.depth_unit_m = f.depth_unit_m;
  p.depth = image_array(f.depth);
  p.K = intrinsics_dict(f.K);
  if (f.points) p.points = vector_image_array(*f.points);
  if (f.confidence) p.confidence = image_array(*f.confidence);
  if (f.sensor_normals) p.sensor_normals = vector_image_array(*f.sensor_normals);
  return p;
}

//! An opened source; iterating yields frames until the end of a finite source.
class PySource {
 public:
  PySource(std::unique_ptr<RangeSource> source, int timeout_ms)
      : source_(std::move(source)), timeout_(timeout_ms) {
    py::gil_scoped_release release;
    source_->open();
  }

  PyFrame next() {
    if (!source_) throw py::stop_iteration();
    RangeFrame frame;
    for (;;) {
      ReadStatus status;
      {
        py::gil_scoped_release release;
        status = source_->next(frame, timeout_);
      }
      switch (status) {
        case ReadStatus::kOk:
          return to_python(frame);
        case ReadStatus::kTimeout:
          if (PyErr_CheckSignals() != 0) throw py::error_already_set();
          continue;  // a live source: wait again (Ctrl-C interrupts)
        case ReadStatus::kEndOfStream:
          throw py::stop_iteration();
        case ReadStatus::kDisconnected:
          throw UnavailableError(info_uri() + ": device disconnected: " + source_->last_error());
        case ReadStatus::kError:
          throw InputError(info_uri() + ": frame could not be read: " + source_->last_error());
      }
    }
  }

  py::dict info() const {
    if (!source_) throw OptionError("source is closed");
    const SourceInfo i = source_->info();
    py::dict d;
    d["uri"] = i.uri;
    d["kind"] = i.kind;
    d["vendor"] = i.vendor;
    d["name"] = i.name;
    d["serial"] = i.serial;
    d["usb_id"] = i.usb_id;
    d["firmware"] = i.firmware;
    d["is_live"] = i.is_live;
    d["frame_count"] =
        i.frame_count ? py::object(py::int_(*i.frame_count)) : py::object(py::none());
    d["K"] = intrinsics_dict(i.K);
    d["depth_unit_m"] = i.depth_unit_m;
    d["noise_model"] = i.noise_model;
    return d;
  }

  void close() {
    if (!source_) return;
    py::gil_scoped_release release;
    source_->close();
    source_.reset();
  }

 private:
  std::string info_uri() const { return source_->info().uri; }

  std::unique_ptr<RangeSource> source_;
  std::chrono::milliseconds timeout_;
};

}  // namespace

void bind_sources(py::module_& m) {
  py::class_<PyFrame>(m, "Frame", "One range frame (camera frame: x right, y down, z forward).")
      .def_readonly("index", &PyFrame::index, "source frame index (a gap means dropped frames)")
      .def_readonly("device_ts_us", &PyFrame::device_ts_us, "device timestamp (microseconds)")
      .def_readonly("host_ts_ns", &PyFrame::host_ts_ns, "host receive time (steady clock, ns)")
      .def_readonly("depth_unit_m", &PyFrame::depth_unit_m, "metres per depth unit")
      .def_readonly("depth", &PyFrame::depth, "(H, W) uint16 depth, 0 = invalid")
      .def_readonly("K", &PyFrame::K, "intrinsics: fx fy cx cy (pixels), width, height, dist")
      .def_readonly("points", &PyFrame::points, "(H, W, 3) float32 metres (NaN = invalid) or None")
      .def_readonly("confidence", &PyFrame::confidence, "(H, W) float32 in [0, 1] or None")
      .def_readonly("sensor_normals", &PyFrame::sensor_normals, "(H, W, 3) float32 or None")
      .def("__repr__", [](const PyFrame& f) {
        return "<scanclean.Frame " + std::to_string(f.index) + " " +
               std::to_string(f.depth.shape(1)) + "x" + std::to_string(f.depth.shape(0)) + ">";
      });
  py::class_<PySource>(m, "Source", "An opened range source; iterate it for frames.")
      .def("__iter__", [](PySource& s) -> PySource& { return s; })
      .def("__next__", &PySource::next)
      .def_property_readonly("info", &PySource::info, "what the source is (dict)")
      .def("close", &PySource::close, "releases the device or files")
      .def("__enter__", [](PySource& s) -> PySource& { return s; })
      .def("__exit__", [](PySource& s, const py::args&) { s.close(); });
  m.def(
      "open_source",
      [](const std::string& uri, const std::string& depth_format, bool recorded_pacing,
         bool depth_100um, int timeout_ms) {
        if (timeout_ms <= 0)
          throw OptionError("timeout_ms: expected > 0, got " + std::to_string(timeout_ms));
        SourceOptions o;
        o.depth_format = depth_format;
        o.recorded_pacing = recorded_pacing;
        o.depth_100um = depth_100um;
        return std::make_unique<PySource>(make_range_source(uri, o), timeout_ms);
      },
      py::arg("uri"), py::kw_only(), py::arg("depth_format") = "auto",
      py::arg("recorded_pacing") = false, py::arg("depth_100um") = false,
      py::arg("timeout_ms") = 2000,
      R"doc(Opens a range source, as the program's --source does: "openni2://", "<file>.oni",
"vsensor://...", a recording folder, depth images (with intrinsics.json) or a structured-light
capture. Iterate it for Frame objects; a finite source stops at its end.)doc");
}

}  // namespace scanclean::python

#include "cloud_arrays.h"

#include <algorithm>
#include <string>
#include <vector>

#include "scanclean/core/errors.h"
#include "scanclean/io/point_cloud_io.h"

namespace py = pybind11;

namespace scanclean::python {
namespace {

std::string shape_of(const py::array& a) {
  std::string s = "(";
  for (py::ssize_t i = 0; i < a.ndim(); ++i) s += (i ? ", " : "") + std::to_string(a.shape(i));
  return s + (a.ndim() == 1 ? ",)" : ")");
}

template <class T>
py::array_t<T> typed(const py::handle& h, const char* what) {
  if (!py::isinstance<py::array>(h) && !py::isinstance<py::sequence>(h))
    throw OptionError(std::string(what) + ": expected a numpy array, got " +
                      std::string(py::str(py::type::of(h))));
  return py::array_t<T, py::array::c_style | py::array::forcecast>::ensure(h);
}

void check_rows(const py::array& a, std::size_t n, int cols, const char* what) {
  const bool ok = cols == 0 ? (a.ndim() == 1 && static_cast<std::size_t>(a.shape(0)) == n)
                            : (a.ndim() == 2 && static_cast<std::size_t>(a.shape(0)) == n &&
                               a.shape(1) == cols);
  if (!ok)
    throw OptionError(std::string(what) + ": expected shape (" + std::to_string(n) +
                      (cols == 0 ? ",)" : ", " + std::to_string(cols) + ")") + ", got " +
                      shape_of(a));
}

template <class T>
py::array_t<T> make_array(std::vector<py::ssize_t> shape, const T* data) {
  py::array_t<T> a(shape);
  std::size_t count = 1;
  for (auto s : shape) count *= static_cast<std::size_t>(s);
  std::copy(data, data + count, a.mutable_data());
  return a;
}

py::array attribute_array(const Attribute& attr) {
  const auto n = static_cast<py::ssize_t>(attr.values.size());
  auto fill = [&](auto tag) {
    using T = decltype(tag);
    py::array_t<T> a(n);
    T* out = a.mutable_data();
    for (py::ssize_t i = 0; i < n; ++i) out[i] = static_cast<T>(attr.values[i]);
    return py::array(a);
  };
  switch (attr.type) {
    case AttributeType::kUInt8:
      return fill(std::uint8_t{});
    case AttributeType::kInt32:
      return fill(std::int32_t{});
    case AttributeType::kUInt32:
      return fill(std::uint32_t{});
    case AttributeType::kFloat32:
      return fill(float{});
    case AttributeType::kFloat64:
      break;
  }
  return fill(double{});
}

//! The attribute type that holds a numpy dtype exactly.
AttributeType attribute_type(const py::array& a, const std::string& key) {
  const py::dtype d = a.dtype();
  if (d.is(py::dtype::of<std::uint8_t>()) || d.is(py::dtype::of<bool>()))
    return AttributeType::kUInt8;
  if (d.is(py::dtype::of<std::int32_t>())) return AttributeType::kInt32;
  if (d.is(py::dtype::of<std::uint32_t>())) return AttributeType::kUInt32;
  if (d.is(py::dtype::of<float>())) return AttributeType::kFloat32;
  if (d.is(py::dtype::of<double>())) return AttributeType::kFloat64;
  throw OptionError("attribute \"" + key + "\": dtype " + d.attr("name").cast<std::string>() +
                    " cannot be stored; use uint8, int32, uint32, float32 or float64 (astype)");
}

}  // namespace

std::vector<Eigen::Vector3d> points_from_array(const py::handle& array, const char* what) {
  const auto a = typed<double>(array, what);
  if (a.ndim() != 2 || a.shape(1) != 3)
    throw OptionError(std::string(what) + ": expected shape (N, 3), got " + shape_of(a));
  std::vector<Eigen::Vector3d> out(static_cast<std::size_t>(a.shape(0)));
  const double* p = a.data();
  for (std::size_t i = 0; i < out.size(); ++i) out[i] = {p[3 * i], p[3 * i + 1], p[3 * i + 2]};
  return out;
}

std::vector<Eigen::Vector3f> normals_from_array(const py::handle& array, std::size_t n,
                                                const char* what) {
  const auto a = typed<float>(array, what);
  check_rows(a, n, 3, what);
  std::vector<Eigen::Vector3f> out(n);
  const float* p = a.data();
  for (std::size_t i = 0; i < n; ++i) out[i] = {p[3 * i], p[3 * i + 1], p[3 * i + 2]};
  return out;
}

std::vector<float> floats_from_array(const py::handle& array, std::size_t n, const char* what) {
  const auto a = typed<float>(array, what);
  check_rows(a, n, 0, what);
  return {a.data(), a.data() + n};
}

py::dict cloud_to_dict(const PointCloud& c) {
  py::dict d;
  const auto n = static_cast<py::ssize_t>(c.size());
  py::array_t<double> points({n, py::ssize_t{3}});
  double* p = points.mutable_data();
  for (std::size_t i = 0; i < c.size(); ++i)
    for (int k = 0; k < 3; ++k) p[3 * i + k] = c.positions[i][k];
  d["points"] = points;
  if (c.has_normals()) {
    py::array_t<float> a({n, py::ssize_t{3}});
    float* q = a.mutable_data();
    for (std::size_t i = 0; i < c.size(); ++i)
      for (int k = 0; k < 3; ++k) q[3 * i + k] = c.normals[i][k];
    d["normals"] = a;
  }
  if (c.has_confidences()) d["confidences"] = make_array<float>({n}, c.confidences.data());
  if (c.has_intensities()) d["intensities"] = make_array<float>({n}, c.intensities.data());
  if (c.has_colors())
    d["colors"] = make_array<std::uint8_t>({n, py::ssize_t{4}}, c.colors.data()->data());
  for (const auto& attr : c.attributes) d[py::str(attr.name)] = attribute_array(attr);
  if (!c.grid.empty())
    d["grid"] = make_array<std::int32_t>({c.grid.rows, c.grid.cols}, c.grid.index.data());
  return d;
}

PointCloud cloud_from_object(const py::handle& object) {
  PointCloud c;
  if (!py::isinstance<py::dict>(object)) {
    c.positions = points_from_array(object, "points");
    return c;
  }
  const auto d = py::reinterpret_borrow<py::dict>(object);
  if (!d.contains("points")) throw OptionError("cloud: the dict has no \"points\" array");
  c.positions = points_from_array(d["points"], "points");
  const std::size_t n = c.size();
  for (const auto& [key_handle, value] : d) {
    const std::string key = py::str(key_handle);
    if (key == "points" || value.is_none() || py::isinstance<py::dict>(value)) continue;
    if (key == "normals") {
      c.normals = normals_from_array(value, n, "normals");
    } else if (key == "confidences") {
      c.confidences = floats_from_array(value, n, "confidences");
    } else if (key == "intensities") {
      c.intensities = floats_from_array(value, n, "intensities");
    } else if (key == "colors") {
      const auto a = typed<std::uint8_t>(value, "colors");
      if (a.ndim() != 2 || static_cast<std::size_t>(a.shape(0)) != n ||
          (a.shape(1) != 3 && a.shape(1) != 4))
        throw OptionError("colors: expected shape (" + std::to_string(n) + ", 3 or 4) uint8, got " +
                          shape_of(a));
      const auto cols = static_cast<std::size_t>(a.shape(1));
      c.colors.resize(n);
      for (std::size_t i = 0; i < n; ++i)
        for (std::size_t k = 0; k < 4; ++k)
          c.colors[i][k] = k < cols ? a.data()[cols * i + k] : std::uint8_t{255};
    } else if (key == "grid") {
      const auto a = typed<std::int32_t>(value, "grid");
      if (a.ndim() != 2) throw OptionError("grid: expected shape (rows, cols), got " + shape_of(a));
      c.grid.rows = static_cast<int>(a.shape(0));
      c.grid.cols = static_cast<int>(a.shape(1));
      c.grid.index.assign(a.data(), a.data() + a.size());
      for (const std::int32_t i : c.grid.index)
        if (i < -1 || i >= static_cast<std::int64_t>(n))
          throw OptionError("grid: index " + std::to_string(i) + " outside [-1, " +
                            std::to_string(n) + ")");
    } else if (py::isinstance<py::array>(value)) {
      const auto a = py::reinterpret_borrow<py::array>(value);
      const AttributeType type = attribute_type(a, key);
      const auto values = typed<double>(a, key.c_str());
      check_rows(values, n, 0, key.c_str());
      c.set_attribute(key, type, {values.data(), values.data() + n});
    }
  }
  return c;
}

void bind_cloud_io(py::module_& m) {
  m.def(
      "read",
      [](const std::string& path) {
        ReadReport report;
        PointCloud cloud;
        {
          py::gil_scoped_release release;
          cloud = read_point_cloud(path, &report);
        }
        if (!report.warnings.empty() || report.dropped_invalid > 0) {
          const py::object warn = py::module_::import("warnings").attr("warn");
          for (const auto& w : report.warnings) warn(w);
          if (report.dropped_invalid > 0)
            warn(path + ": " + std::to_string(report.dropped_invalid) +
                 " invalid points dropped while reading");
        }
        return cloud_to_dict(cloud);
      },
      py::arg("path"),
      "Reads a .ply, .pcd, .xyz or .txt cloud (metres) into a dict of numpy arrays: points (N, 3) "
      "float64 and, when the file has them, normals, confidences, intensities, colors (N, 4) "
      "uint8, "
      "every other per-point field by name, and grid for organized clouds. Reader warnings are "
      "issued as Python warnings.");
  m.def(
      "write",
      [](const std::string& path, const py::handle& cloud, bool ascii,
         const std::string& pcd_encoding, const std::string& provenance) {
        WriteOptions w;
        w.pcd_encoding = pcd_encoding;
        w.provenance = provenance;
        if (ascii) w.ply_encoding = PlyEncoding::kAscii;
        validate(w);
        const PointCloud c = cloud_from_object(cloud);
        py::gil_scoped_release release;
        write_point_cloud(path, c, w);
      },
      py::arg("path"), py::arg("cloud"), py::kw_only(), py::arg("ascii") = false,
      py::arg("pcd_encoding") = "binary_compressed", py::arg("provenance") = "",
      "Writes a cloud atomically, format by extension (.ply, .pcd, .xyz). cloud: a dict as read() "
      "or robust_filter() returns (nested dicts such as 'stats' are ignored) or an (N, 3) array of "
      "points. ascii: ASCII PLY; pcd_encoding: ascii | binary | binary_compressed; provenance: a "
      "header comment of PLY and PCD files (e.g. how the cloud was made).");
}

}  // namespace scanclean::python

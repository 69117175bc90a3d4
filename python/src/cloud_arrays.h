#pragma once
//! \file cloud_arrays.h
//! PointCloud <-> Python dict of numpy arrays, for the scanclean Python module.
//!
//! Keys: "points" (N, 3) float64 metres, always; "normals" (N, 3) float32, "confidences" (N,)
//! float32, "intensities" (N,) float32, "colors" (N, 4) uint8 RGBA, when present; every named
//! attribute (e.g. the filter's "likelihood", "flags") as an (N,) array of its stored type;
//! "grid" (rows, cols) int32 of point indices (-1 = empty) for organized clouds.

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include "scanclean/core/point_cloud.h"

namespace scanclean::python {

//! The cloud as a dict of numpy arrays (copies).
pybind11::dict cloud_to_dict(const PointCloud& cloud);

//! A cloud from a dict as cloud_to_dict makes it (other 1-D arrays of length N become
//! attributes; values that are not arrays, such as nested dicts, are ignored) or from an (N, 3)
//! array of points. \throw OptionError naming the key, the shape or dtype found and the one
//! expected.
PointCloud cloud_from_object(const pybind11::handle& object);

//! Positions from an (N, 3) array (any real dtype, converted to float64).
std::vector<Eigen::Vector3d> points_from_array(const pybind11::handle& array, const char* what);
//! Normals from an (N, 3) array (converted to float32).
std::vector<Eigen::Vector3f> normals_from_array(const pybind11::handle& array, std::size_t n,
                                                const char* what);
//! Per-point float32 values from an (N,) array.
std::vector<float> floats_from_array(const pybind11::handle& array, std::size_t n,
                                     const char* what);

//! Binds read() and write().
void bind_cloud_io(pybind11::module_& m);

}  // namespace scanclean::python

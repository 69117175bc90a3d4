#pragma once
//! \file source_binding.h
//! scanclean.open_source(): any range source of drivers/source_factory (live OpenNI2 sensors,
//! .oni files, the virtual sensor, recording folders, depth images, structured-light captures)
//! as a Python iterator of frames.

#include <pybind11/pybind11.h>

namespace scanclean::python {

//! Binds open_source(), Source and Frame.
void bind_sources(pybind11::module_& m);

}  // namespace scanclean::python

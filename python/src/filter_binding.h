#pragma once
//! \file filter_binding.h
//! scanclean.robust_filter(): the filter of scanclean/filter/robust_filter.h on numpy arrays.

#include <pybind11/pybind11.h>

namespace scanclean::python {

//! Binds robust_filter() and default_filter_options().
void bind_filter(pybind11::module_& m);

}  // namespace scanclean::python

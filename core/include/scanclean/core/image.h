#pragma once
//! \file image.h
//! A minimal owning 2-D image, row-major, with no dependency on OpenCV (SDK types stay out of
//! public headers; conversions live in the modules that use OpenCV).

#include <cassert>
#include <cstddef>
#include <vector>

namespace scanclean {

template <class T>
struct Image {
  int width = 0;
  int height = 0;
  std::vector<T> data;  //!< width*height values, row-major (v * width + u)

  Image() = default;
  Image(int w, int h, const T& fill = T{})
      : width(w), height(h), data(static_cast<std::size_t>(w) * h, fill) {}

  bool empty() const { return data.empty(); }
  std::size_t size() const { return data.size(); }
  T& operator()(int u, int v) {
    assert(u >= 0 && v >= 0 && u < width && v < height);
    return data[static_cast<std::size_t>(v) * width + u];
  }
  const T& operator()(int u, int v) const {
    assert(u >= 0 && v >= 0 && u < width && v < height);
    return data[static_cast<std::size_t>(v) * width + u];
  }
};

}  // namespace scanclean

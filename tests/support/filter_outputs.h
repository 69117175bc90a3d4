#pragma once
//! Test helpers over the filter's output clouds.

#include <gtest/gtest.h>

#include <cstddef>
#include <cstdint>
#include <map>

#include "scanclean/core/point_cloud.h"

namespace scanclean::test {

//! The output points of `c` by their input point (the "source_index" attribute): source -> the
//! output's index in c. Each source must appear once (checked).
inline std::map<std::uint32_t, std::size_t> by_source(const PointCloud& c) {
  std::map<std::uint32_t, std::size_t> m;
  const Attribute* si = c.find_attribute("source_index");
  for (std::size_t k = 0; si && k < c.size(); ++k) {
    const auto s = static_cast<std::uint32_t>(si->values[k]);
    EXPECT_EQ(m.count(s), 0u) << "source " << s << " twice";
    m[s] = k;
  }
  return m;
}

}  // namespace scanclean::test

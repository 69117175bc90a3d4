#pragma once
// Internal: the binary encoding of PLY values, shared by the whole-file writer (ply_write.cpp)
// and the streaming writer (ply_stream_writer.cpp): little-endian values, integer attributes
// rounded and clamped to their type, the PLY type names and property-name sanitising.

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>

#include "scanclean/core/point_cloud.h"

namespace scanclean::io_detail {

//! Appends `v` little-endian.
template <class T>
void put_le(std::string& buf, T v) {
  if constexpr (std::endian::native == std::endian::big && sizeof(T) > 1) {
    unsigned char b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    std::reverse(b, b + sizeof(T));
    buf.append(reinterpret_cast<const char*>(b), sizeof(T));
  } else {
    buf.append(reinterpret_cast<const char*>(&v), sizeof(T));
  }
}

//! `v` rounded to the nearest I, clamped to I's range; NaN gives 0.
template <class I>
I clamp_int(double v) {
  if (!(v == v)) return 0;
  const double lo = static_cast<double>(std::numeric_limits<I>::min());
  const double hi = static_cast<double>(std::numeric_limits<I>::max());
  return static_cast<I>(std::llround(std::clamp(v, lo, hi)));
}

//! The PLY property type of an attribute type ("uchar", "int", "uint", "float", "double").
inline const char* ply_type_name(AttributeType t) {
  switch (t) {
    case AttributeType::kUInt8:
      return "uchar";
    case AttributeType::kInt32:
      return "int";
    case AttributeType::kUInt32:
      return "uint";
    case AttributeType::kFloat32:
      return "float";
    case AttributeType::kFloat64:
      return "double";
  }
  return "double";
}

//! Appends `v` as a binary value of type `t`.
inline void put_ply_binary(std::string& buf, AttributeType t, double v) {
  switch (t) {
    case AttributeType::kUInt8:
      put_le(buf, clamp_int<std::uint8_t>(v));
      break;
    case AttributeType::kInt32:
      put_le(buf, clamp_int<std::int32_t>(v));
      break;
    case AttributeType::kUInt32:
      put_le(buf, clamp_int<std::uint32_t>(v));
      break;
    case AttributeType::kFloat32:
      put_le(buf, static_cast<float>(v));
      break;
    case AttributeType::kFloat64:
      put_le(buf, v);
      break;
  }
}

//! A property name without whitespace ("unnamed" when empty).
inline std::string sanitize_ply_name(std::string name) {
  for (char& c : name)
    if (c == ' ' || c == '\t' || c == '\n' || c == '\r') c = '_';
  return name.empty() ? std::string("unnamed") : name;
}

}  // namespace scanclean::io_detail

#pragma once
// Helpers for the io tests: files written from strings/bytes, seeded random clouds.

#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>

#include "scanclean/core/errors.h"
#include "scanclean/core/point_cloud.h"
#include "support/synthetic.h"

namespace scanclean::test {

inline std::filesystem::path write_bytes(const std::filesystem::path& p, const std::string& s) {
  std::ofstream out(p, std::ios::binary);
  out.write(s.data(), static_cast<std::streamsize>(s.size()));
  return p;
}

inline std::string read_bytes(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

template <class T>
std::string bytes_le(T v) {
  std::string s(sizeof(T), '\0');
  std::memcpy(s.data(), &v, sizeof(T));
  return s;
}

template <class T>
std::string bytes_be(T v) {
  std::string s = bytes_le(v);
  return std::string(s.rbegin(), s.rend());
}

//! The message of the InputError thrown by f, or "" (and a test failure) if none is thrown.
template <class F>
std::string input_error_of(F&& f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "expected InputError, got another exception: " << e.what();
    return "";
  }
  ADD_FAILURE() << "expected InputError, nothing thrown";
  return "";
}

//! A cloud with every optional array and one attribute per AttributeType, with values that
//! exercise each type's range. Seeded.
inline PointCloud full_cloud(std::size_t n, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  PointCloud c;
  for (std::size_t i = 0; i < n; ++i) {
    // float-representable positions so that the float path is taken
    c.positions.push_back(test::draw_point(rng, u, u, u).cast<float>().cast<double>());
    c.normals.push_back(test::draw_point(rng, u, u, u).cast<float>().normalized());
    c.confidences.push_back(float(0.5 + 0.5 * u(rng)));
    c.intensities.push_back(float(100 * u(rng)));
    c.colors.push_back({std::uint8_t(rng() & 255), std::uint8_t(rng() & 255),
                        std::uint8_t(rng() & 255), std::uint8_t(rng() & 255)});
  }
  std::vector<double> u8(n), i32(n), u32(n), f32(n), f64(n);
  for (std::size_t i = 0; i < n; ++i) {
    u8[i] = double(rng() % 256);
    i32[i] = double(std::int32_t(rng()));
    u32[i] = double(std::uint32_t(rng()));
    f32[i] = double(float(u(rng) * 1e3));
    f64[i] = u(rng) * 1e-3 + 12345.678901234567;
  }
  if (n > 0) {
    u8[0] = 255;
    i32[0] = -2147483648.0;
    u32[0] = 4294967295.0;
  }
  c.set_attribute("flags", AttributeType::kUInt8, u8);
  c.set_attribute("delta", AttributeType::kInt32, i32);
  c.set_attribute("source_index", AttributeType::kUInt32, u32);
  c.set_attribute("likelihood", AttributeType::kFloat32, f32);
  c.set_attribute("time", AttributeType::kFloat64, f64);
  return c;
}

//! Expects b to equal a exactly in every array (positions compared exactly too).
inline void expect_same_cloud(const PointCloud& a, const PointCloud& b, bool with_extras = true) {
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) ASSERT_EQ(a.positions[i], b.positions[i]) << i;
  if (!with_extras) return;
  ASSERT_EQ(a.normals.size(), b.normals.size());
  for (std::size_t i = 0; i < a.normals.size(); ++i) ASSERT_EQ(a.normals[i], b.normals[i]) << i;
  EXPECT_EQ(a.confidences, b.confidences);
  EXPECT_EQ(a.intensities, b.intensities);
  EXPECT_EQ(a.colors, b.colors);
  ASSERT_EQ(a.attributes.size(), b.attributes.size());
  for (const auto& x : a.attributes) {
    const Attribute* y = b.find_attribute(x.name);
    ASSERT_NE(y, nullptr) << x.name;
    EXPECT_EQ(int(x.type), int(y->type)) << x.name;
    EXPECT_EQ(x.values, y->values) << x.name;
  }
  EXPECT_EQ(a.grid.rows, b.grid.rows);
  EXPECT_EQ(a.grid.cols, b.grid.cols);
  EXPECT_EQ(a.grid.index, b.grid.index);
}

}  // namespace scanclean::test

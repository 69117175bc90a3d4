#pragma once
//! \file rng.h
//! A seeded, portable random source for the benchmark: std::mt19937_64 for the bits and our own
//! transforms (the standard distributions are implementation-defined, so results would differ
//! between standard libraries).

#include <cmath>
#include <cstdint>
#include <random>

namespace scanclean::bench {

class Rng {
 public:
  explicit Rng(std::uint64_t seed) : engine_(seed) {}
  //! Uniform in [0, 1).
  double uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  //! Uniform integer in [0, n).
  std::uint64_t index(std::uint64_t n) { return static_cast<std::uint64_t>(uniform() * n); }
  //! Standard normal (Box-Muller, one value per call).
  double normal() {
    double u1 = uniform();
    while (u1 <= 0.0) u1 = uniform();
    const double u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * M_PI * u2);
  }
  std::uint64_t bits() { return engine_(); }

 private:
  std::mt19937_64 engine_;
};

//! A seed derived from a base seed and labels (splitmix64 mixing), so every instance of the
//! protocol has its own independent, reproducible stream.
inline std::uint64_t derive_seed(std::uint64_t base, std::uint64_t a, std::uint64_t b = 0,
                                 std::uint64_t c = 0) {
  std::uint64_t x = base;
  for (std::uint64_t v : {a, b, c}) {
    x ^= v + 0x9e3779b97f4a7c15ULL + (x << 6) + (x >> 2);
    x += 0x9e3779b97f4a7c15ULL;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
    x ^= x >> 31;
  }
  return x;
}

}  // namespace scanclean::bench

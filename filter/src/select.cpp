#include "select.h"

#include <immintrin.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>

#include "avx2_select.h"

namespace scanclean::detail {
namespace {

bool have_avx2();

// The value of rank k among v[0, n) by counting, for each candidate, the values below it and at
// or below it (8 at a time, the tail one by one); false when no value has rank k (a NaN among
// them: comparisons with it are all false).
[[gnu::target("avx2")]] bool rank_select_avx2(const float* v, std::size_t n, std::size_t k,
                                              float& out) {
  const std::size_t full = n - n % 8;
  for (std::size_t i = 0; i < n; ++i) {
    const __m256 x = _mm256_set1_ps(v[i]);
    std::size_t lt = 0, le = 0;
    for (std::size_t j = 0; j < full; j += 8) {
      const __m256 y = _mm256_loadu_ps(v + j);
      lt += static_cast<std::size_t>(__builtin_popcount(
          static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(y, x, _CMP_LT_OQ)))));
      le += static_cast<std::size_t>(__builtin_popcount(
          static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(y, x, _CMP_LE_OQ)))));
    }
    for (std::size_t j = full; j < n; ++j) {
      lt += v[j] < v[i] ? 1 : 0;
      le += v[j] <= v[i] ? 1 : 0;
    }
    if (lt <= k && k < le) {
      out = v[i];
      return true;
    }
  }
  return false;
}

}  // namespace

float kth_smallest_small(float* v, std::size_t n, std::size_t k) {
  float out = 0;
  if (n <= kSmallSelect && have_avx2() && rank_select_avx2(v, n, k, out)) return out;
  std::nth_element(v, v + k, v + n);
  return v[k];
}

float kth_smallest_between(float* v, std::size_t n, std::size_t k, float lower, float upper) {
  constexpr std::size_t kBins = 64;
  const float scale = static_cast<float>(kBins) / (upper - lower);
  if (n <= kBins || !(upper > lower) || !(scale > 0) || !std::isfinite(scale))
    return kth_smallest_small(v, n, k);
  // Monotone in x (a difference, a product with a positive constant, then clamped truncation);
  // NaN goes last.
  auto bin = [scale, lower](float x) -> std::size_t {
    const float t = (x - lower) * scale;
    if (t >= static_cast<float>(kBins - 1) || t != t) return kBins - 1;
    return t >= 1.0f ? static_cast<std::size_t>(t) : 0;
  };
  // Four interleaved counts, so that runs of values in one bin do not wait on each other's
  // increments.
  std::array<std::array<std::uint32_t, kBins>, 4> counts{};
  std::size_t i = 0;
  for (; i + 4 <= n; i += 4) {
    ++counts[0][bin(v[i])];
    ++counts[1][bin(v[i + 1])];
    ++counts[2][bin(v[i + 2])];
    ++counts[3][bin(v[i + 3])];
  }
  for (; i < n; ++i) ++counts[0][bin(v[i])];
  std::array<std::uint32_t, kBins> count;
  for (std::size_t c = 0; c < kBins; ++c)
    count[c] = (counts[0][c] + counts[1][c]) + (counts[2][c] + counts[3][c]);
  std::size_t b = 0, before = 0;
  while (before + count[b] <= k) before += count[b++];
  std::size_t m = 0;
  for (std::size_t j = 0; j < n; ++j) {
    const float x = v[j];
    v[m] = x;
    m += bin(x) == b ? 1 : 0;
  }
  return kth_smallest_small(v, m, k - before);
}

float kth_smallest_below(float* v, std::size_t n, std::size_t k, float upper) {
  return kth_smallest_between(v, n, k, 0.0f, upper);
}

namespace {

void band_scalar(const float* x, const float* y, const float* z, std::size_t n, const float q[3],
                 float lo2, float hi2, std::size_t& below, float* band, std::size_t& m) {
  for (std::size_t j = 0; j < n; ++j) {
    const float dx = x[j] - q[0], dy = y[j] - q[1], dz = z[j] - q[2];
    const float d2 = dx * dx + dy * dy + dz * dz;
    below += d2 < lo2 ? 1 : 0;
    band[m] = d2;
    m += (d2 >= lo2 && d2 < hi2) ? 1 : 0;
  }
}

// AVX2 without FMA, so the squared distances round as in band_scalar.
[[gnu::target("avx2")]] void band_avx2(const float* x, const float* y, const float* z,
                                       std::size_t n, const float q[3], float lo2, float hi2,
                                       std::size_t& below, float* band, std::size_t& m) {
  const __m256 qx = _mm256_set1_ps(q[0]), qy = _mm256_set1_ps(q[1]), qz = _mm256_set1_ps(q[2]);
  const __m256 lo = _mm256_set1_ps(lo2), hi = _mm256_set1_ps(hi2);
  std::size_t count = 0;
  // The last few points (n not a multiple of 8) through masked loads, not a scalar loop:
  // callers pass the runs of a cell's neighbourhood (about 24 points each at 2.1M), so the tails
  // were a large share.
  for (std::size_t j = 0; j < n; j += 8) {
    const bool whole = n - j >= 8;
    const __m256i lanes = lanes_below(whole ? 8 : n - j);
    const unsigned valid = static_cast<unsigned>(_mm256_movemask_ps(_mm256_castsi256_ps(lanes)));
    const __m256 d2 = whole ? squared_distances8(x + j, y + j, z + j, qx, qy, qz)
                            : squared_distances8_masked(x + j, y + j, z + j, qx, qy, qz, lanes);
    const __m256 under = _mm256_cmp_ps(d2, lo, _CMP_LT_OQ);
    const __m256 in = _mm256_andnot_ps(under, _mm256_cmp_ps(d2, hi, _CMP_LT_OQ));
    count += static_cast<std::size_t>(
        __builtin_popcount(static_cast<unsigned>(_mm256_movemask_ps(under)) & valid));
    // The band's lanes, left-packed; all 8 are stored, m advances by the selected.
    m += store_left_packed(band + m, d2, static_cast<unsigned>(_mm256_movemask_ps(in)) & valid);
  }
  below += count;
}

void within_scalar(const float* x, const float* y, const float* z, const std::uint32_t* cnt,
                   const float* lik, std::size_t n, const float q[3], float r2, float lik_max,
                   WithinCounts& out) {
  for (std::size_t j = 0; j < n; ++j) {
    const float dx = x[j] - q[0], dy = y[j] - q[1], dz = z[j] - q[2];
    const float d2 = dx * dx + dy * dy + dz * dz;
    if (!(d2 < r2)) continue;
    out.sum += cnt[j];
    ++out.n;
    if (lik) out.at_or_below += lik[j] <= lik_max ? 1 : 0;
  }
}

// AVX2 without FMA, so the squared distances round as in within_scalar. The cnt lanes sum in
// 32 bits (the caller keeps a call's sum below 2^32).
[[gnu::target("avx2")]] void within_avx2(const float* x, const float* y, const float* z,
                                         const std::uint32_t* cnt, const float* lik, std::size_t n,
                                         const float q[3], float r2, float lik_max,
                                         WithinCounts& out) {
  const __m256 qx = _mm256_set1_ps(q[0]), qy = _mm256_set1_ps(q[1]), qz = _mm256_set1_ps(q[2]);
  const __m256 rr = _mm256_set1_ps(r2), lm = _mm256_set1_ps(lik_max);
  __m256i sum = _mm256_setzero_si256();
  std::size_t within = 0, below = 0;
  for (std::size_t j = 0; j < n; j += 8) {  // the last few through masked loads, as band_avx2
    const bool whole = n - j >= 8;
    const __m256i lanes = lanes_below(whole ? 8 : n - j);
    const __m256 d2 = whole ? squared_distances8(x + j, y + j, z + j, qx, qy, qz)
                            : squared_distances8_masked(x + j, y + j, z + j, qx, qy, qz, lanes);
    const __m256 in = _mm256_and_ps(_mm256_cmp_ps(d2, rr, _CMP_LT_OQ), _mm256_castsi256_ps(lanes));
    const __m256i c = whole ? _mm256_loadu_si256(reinterpret_cast<const __m256i*>(cnt + j))
                            : _mm256_maskload_epi32(reinterpret_cast<const int*>(cnt + j), lanes);
    sum = _mm256_add_epi32(sum, _mm256_and_si256(c, _mm256_castps_si256(in)));
    within +=
        static_cast<std::size_t>(__builtin_popcount(static_cast<unsigned>(_mm256_movemask_ps(in))));
    if (lik) {
      const __m256 l = whole ? _mm256_loadu_ps(lik + j) : _mm256_maskload_ps(lik + j, lanes);
      const __m256 le = _mm256_and_ps(in, _mm256_cmp_ps(l, lm, _CMP_LE_OQ));
      below += static_cast<std::size_t>(
          __builtin_popcount(static_cast<unsigned>(_mm256_movemask_ps(le))));
    }
  }
  alignas(32) std::uint32_t lanes[8];
  _mm256_store_si256(reinterpret_cast<__m256i*>(lanes), sum);
  std::uint32_t total = 0;
  for (std::uint32_t v : lanes) total += v;
  out.sum += total;
  out.n += within;
  out.at_or_below += below;
}

// The squared distance from p to the box [lo, hi]: the gaps per axis, rounded in float.
inline float box_gap2(float x, float y, float z, const float lo[3], const float hi[3]) {
  const float ex = std::max(std::max(lo[0] - x, x - hi[0]), 0.0f);
  const float ey = std::max(std::max(lo[1] - y, y - hi[1]), 0.0f);
  const float ez = std::max(std::max(lo[2] - z, z - hi[2]), 0.0f);
  return ex * ex + ey * ey + ez * ez;
}

// The kept points' coordinates, and their values of `slot` and `extra` when not null.
void near_box_scalar(const float* x, const float* y, const float* z, const std::uint32_t* slot,
                     const float* extra, std::size_t n, const float lo[3], const float hi[3],
                     float r2, NearBoxOut& out, std::size_t& m) {
  for (std::size_t j = 0; j < n; ++j) {
    out.x[m] = x[j];
    out.y[m] = y[j];
    out.z[m] = z[j];
    if (slot) out.slot[m] = slot[j];
    if (extra) out.extra[m] = extra[j];
    m += box_gap2(x[j], y[j], z[j], lo, hi) < r2 ? 1 : 0;
  }
}

// AVX2 without FMA, so the squared gaps round as in near_box_scalar.
[[gnu::target("avx2")]] void near_box_avx2(const float* x, const float* y, const float* z,
                                           const std::uint32_t* slot, const float* extra,
                                           std::size_t n, const float lo[3], const float hi[3],
                                           float r2, NearBoxOut& out, std::size_t& m) {
  const __m256 lx = _mm256_set1_ps(lo[0]), ly = _mm256_set1_ps(lo[1]), lz = _mm256_set1_ps(lo[2]);
  const __m256 hx = _mm256_set1_ps(hi[0]), hy = _mm256_set1_ps(hi[1]), hz = _mm256_set1_ps(hi[2]);
  const __m256 rr = _mm256_set1_ps(r2), zero = _mm256_setzero_ps();
  // The last few points (n not a multiple of 8) through masked loads, which read nothing past
  // the arrays: runs of a cell's neighbourhood are short, and a scalar tail took a fifth of the
  // time.
  for (std::size_t j = 0; j < n; j += 8) {
    const std::size_t left = n - j;
    const bool whole = left >= 8;
    const __m256i in = lanes_below(whole ? 8 : left);
    const __m256 px = whole ? _mm256_loadu_ps(x + j) : _mm256_maskload_ps(x + j, in);
    const __m256 py = whole ? _mm256_loadu_ps(y + j) : _mm256_maskload_ps(y + j, in);
    const __m256 pz = whole ? _mm256_loadu_ps(z + j) : _mm256_maskload_ps(z + j, in);
    const __m256 ex =
        _mm256_max_ps(_mm256_max_ps(_mm256_sub_ps(lx, px), _mm256_sub_ps(px, hx)), zero);
    const __m256 ey =
        _mm256_max_ps(_mm256_max_ps(_mm256_sub_ps(ly, py), _mm256_sub_ps(py, hy)), zero);
    const __m256 ez =
        _mm256_max_ps(_mm256_max_ps(_mm256_sub_ps(lz, pz), _mm256_sub_ps(pz, hz)), zero);
    const __m256 g2 = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(ex, ex), _mm256_mul_ps(ey, ey)),
                                    _mm256_mul_ps(ez, ez));
    const unsigned mask =
        static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(g2, rr, _CMP_LT_OQ))) &
        static_cast<unsigned>(_mm256_movemask_ps(_mm256_castsi256_ps(in)));
    if (mask == 0) continue;
    if (slot)
      store_left_packed(out.slot + m,
                        whole ? _mm256_loadu_si256(reinterpret_cast<const __m256i*>(slot + j))
                              : _mm256_maskload_epi32(reinterpret_cast<const int*>(slot + j), in),
                        mask);
    if (extra)
      store_left_packed(out.extra + m,
                        whole ? _mm256_loadu_ps(extra + j) : _mm256_maskload_ps(extra + j, in),
                        mask);
    store_left_packed(out.x + m, px, mask);
    store_left_packed(out.y + m, py, mask);
    m += store_left_packed(out.z + m, pz, mask);
  }
}

bool have_avx2() {
  static const bool yes = __builtin_cpu_supports("avx2");
  return yes;
}

}  // namespace

void count_below_and_band(const float* x, const float* y, const float* z, std::size_t n,
                          const float q[3], float lo2, float hi2, std::size_t& below, float* band,
                          std::size_t& m) {
  if (have_avx2())
    band_avx2(x, y, z, n, q, lo2, hi2, below, band, m);
  else
    band_scalar(x, y, z, n, q, lo2, hi2, below, band, m);
}

void select_near_box(const float* x, const float* y, const float* z, const std::uint32_t* slot,
                     const float* extra, std::size_t n, const float lo[3], const float hi[3],
                     float r2, NearBoxOut out, std::size_t& m) {
  if (have_avx2())
    near_box_avx2(x, y, z, slot, extra, n, lo, hi, r2, out, m);
  else
    near_box_scalar(x, y, z, slot, extra, n, lo, hi, r2, out, m);
}

bool largest_float_scaled_at_or_below(double ratio, double l, float& bound) {
  if (!(ratio > 0) || !(l >= 0) || !std::isfinite(l)) return false;
  auto holds = [&](float v) { return ratio * static_cast<double>(v) <= l; };
  float t = static_cast<float>(l / ratio);
  if (!std::isfinite(t)) return false;
  const float inf = std::numeric_limits<float>::infinity();
  while (!holds(t)) t = std::nextafter(t, -inf);  // ends by 0, where it holds
  while (t < std::numeric_limits<float>::max() && holds(std::nextafter(t, inf)))
    t = std::nextafter(t, inf);
  bound = t;
  return true;
}

void count_within(const float* x, const float* y, const float* z, const std::uint32_t* cnt,
                  const float* lik, std::size_t n, const float q[3], float r2, float lik_max,
                  WithinCounts& out) {
  if (have_avx2())
    within_avx2(x, y, z, cnt, lik, n, q, r2, lik_max, out);
  else
    within_scalar(x, y, z, cnt, lik, n, q, r2, lik_max, out);
}

}  // namespace scanclean::detail

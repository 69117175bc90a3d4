#include "select.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

// The loops over points are written once with Google Highway and compiled for every instruction
// set it targets on the build machine's architecture (x86: AVX-512, AVX2, SSE4, SSSE3 and a
// portable fallback; ARM: NEON, SVE, ...); the best one the processor has runs. Vectors are
// capped at 8 floats, the padding the callers provide. This file is compiled without
// floating-point contraction (filter/CMakeLists.txt), so every target rounds a squared distance
// as (dx dx + dy dy) + dz dz in float, as a plain loop does: the selections are the same on
// every processor.
#ifndef SCANCLEAN_FILTER_SELECT_COMPRESS_TABLE
#define SCANCLEAN_FILTER_SELECT_COMPRESS_TABLE
namespace scanclean::detail {
// For each set of up to 8 lanes (a mask's bits), the positions of its lanes in order, then zeros:
// the permutation that moves the kept lanes to the front.
struct CompressTable {
  std::uint8_t lanes[256][8];
};
constexpr CompressTable make_compress_table() {
  CompressTable t{};
  for (unsigned bits = 0; bits < 256; ++bits) {
    unsigned k = 0;
    for (unsigned lane = 0; lane < 8; ++lane)
      if (bits >> lane & 1u) t.lanes[bits][k++] = static_cast<std::uint8_t>(lane);
  }
  return t;
}
alignas(64) inline constexpr CompressTable kCompressTable = make_compress_table();
}  // namespace scanclean::detail
#endif

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "select.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace scanclean::detail {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

using D = hn::CappedTag<float, 8>;
using DU = hn::RebindToUnsigned<D>;
using V = hn::Vec<D>;
using M = hn::Mask<D>;
// The loops that read their tails through masked loads (Band, Within, NearBox) need no padding
// and take whole AVX-512 vectors (16 floats) where the processor has them.
#if HWY_ARCH_X86 && HWY_TARGET <= HWY_AVX3
using DL = hn::ScalableTag<float>;
#else
using DL = D;
#endif
using DLU = hn::RebindToUnsigned<DL>;
using VL = hn::Vec<DL>;
using ML = hn::Mask<DL>;

// The lanes [j, j + N) of p, of which those of `in` (the first n - j) are read; the others are
// zero. x86's AVX2 and AVX-512 load the lanes of a mask alone; on the other targets a masked
// load may read the whole vector (and fault past the array's end), so a tail is copied first.
template <class DV>
HWY_INLINE hn::Vec<DV> load(DV dv, const hn::TFromD<DV>* p, bool whole, hn::Mask<DV> in) {
  if (whole) return hn::LoadU(dv, p);
#if HWY_ARCH_X86 && HWY_TARGET <= HWY_AVX2
  return hn::MaskedLoad(in, dv, p);
#else
  HWY_ALIGN hn::TFromD<DV> tail[8] = {};
  const std::size_t n = hn::CountTrue(dv, in);
  for (std::size_t k = 0; k < n; ++k) tail[k] = p[k];
  return hn::Load(dv, tail);
#endif
}

// Stores the lanes of v selected by `keep` at p, in order, and returns their number; the whole
// vector is stored (p needs room for N). Two things Highway 1.0.3 does slowly are avoided:
// - AVX-512 and SVE compress in a register, then store: AVX-512's compressing store to memory
//   (hn::CompressStore there) is microcoded on AMD's Zen 4 and made the scale phase of the 2.1M
//   sphere four times slower.
// - The other targets permute by our own table: hn::Compress there copies its table (1 KiB on
//   AVX2) onto the stack at every call (GCC 12), which made the 2.1M filter twice as slow on AVX2.
template <class DV>
HWY_INLINE std::size_t compress_store(hn::Vec<DV> v, hn::Mask<DV> keep, DV dv, hn::TFromD<DV>* p) {
#if (HWY_ARCH_X86 && HWY_TARGET <= HWY_AVX3) || HWY_TARGET == HWY_SVE || HWY_TARGET == HWY_SVE2 || \
    HWY_TARGET == HWY_SVE_256 || HWY_TARGET == HWY_SVE2_128
  hn::StoreU(hn::Compress(v, keep), dv, p);
  return hn::CountTrue(dv, keep);
#else
  static_assert(hn::MaxLanes(DV()) <= 8, "the table holds 8 lanes");
  std::uint8_t bits[8] = {};
  hn::StoreMaskBits(dv, keep, bits);
  const hn::RebindToUnsigned<DV> du;
  const hn::Rebind<std::uint8_t, DV> d8;
  const auto order = hn::PromoteTo(du, hn::LoadU(d8, kCompressTable.lanes[bits[0]]));
  hn::StoreU(hn::TableLookupLanes(v, hn::IndicesFromVec(dv, order)), dv, p);
  return hwy::PopCount(bits[0]);
#endif
}

// |p - q|^2 rounded as (dx dx + dy dy) + dz dz.
template <class VV>
HWY_INLINE VV squared_distance(VV px, VV py, VV pz, VV qx, VV qy, VV qz) {
  const VV dx = hn::Sub(px, qx), dy = hn::Sub(py, qy), dz = hn::Sub(pz, qz);
  return hn::Add(hn::Add(hn::Mul(dx, dx), hn::Mul(dy, dy)), hn::Mul(dz, dz));
}

// The value of rank k among v[0, n) by counting, for each value, those below it and at or below
// it; false when no value has rank k (a NaN among them: comparisons with it are all false).
bool RankSelect(const float* v, std::size_t n, std::size_t k, float* out) {
  const DL d;
  const std::size_t N = hn::Lanes(d);
  for (std::size_t i = 0; i < n; ++i) {
    const VL x = hn::Set(d, v[i]);
    std::size_t lt = 0, le = 0;
    for (std::size_t j = 0; j < n; j += N) {
      const ML in = hn::FirstN(d, n - j);
      const VL y = load(d, v + j, n - j >= N, in);
      lt += hn::CountTrue(d, hn::And(hn::Lt(y, x), in));
      le += hn::CountTrue(d, hn::And(hn::Le(y, x), in));
    }
    if (lt <= k && k < le) {
      *out = v[i];
      return true;
    }
  }
  return false;
}

// The bins of kth_smallest_between: b = 63 where t = (v - lower) scale is not below 63 (or NaN),
// else trunc(t) where t >= 1, else 0; rounded as the scalar map (no fused multiply-add here).
// bins needs room for n rounded up to a multiple of 8.
void BinsOf(const float* v, std::size_t n, float lower, float scale, std::uint8_t* bins) {
  const D d;
  const hn::RebindToSigned<D> di;
  const hn::Rebind<std::uint8_t, D> d8;
  const std::size_t N = hn::Lanes(d);
  const V lo = hn::Set(d, lower), sc = hn::Set(d, scale);
  const V one = hn::Set(d, 1.0f), top = hn::Set(d, 63.0f), zero = hn::Zero(d);
  for (std::size_t j = 0; j < n; j += N) {
    const V t = hn::Mul(hn::Sub(load(d, v + j, n - j >= N, hn::FirstN(d, n - j)), lo), sc);
    const V low = hn::IfThenElse(hn::Ge(t, one), t, zero);
    const V b = hn::IfThenElse(hn::Lt(t, top), low, top);  // NaN: not below 63
    hn::StoreU(hn::DemoteTo(d8, hn::ConvertTo(di, b)), d8, bins + j);
  }
}

// Moves the values of bin b (bins as BinsOf) to the front of v, in order; returns their count.
std::size_t KeepBin(float* v, const std::uint8_t* bins, std::size_t n, std::uint8_t b) {
  const D d;
  const DU du;
  const hn::Rebind<std::uint8_t, D> d8;
  const std::size_t N = hn::Lanes(d);
  const auto want = hn::Set(du, b);
  std::size_t m = 0, j = 0;
  // Whole vectors: the store at m <= j ends by j + N, within what was read.
  for (; j + N <= n; j += N) {
    const auto keep = hn::Eq(hn::PromoteTo(du, hn::LoadU(d8, bins + j)), want);
    m += compress_store(hn::LoadU(d, v + j), hn::RebindMask(d, keep), d, v + m);
  }
  for (; j < n; ++j) {
    v[m] = v[j];
    m += bins[j] == b ? 1 : 0;
  }
  return m;
}

void Band(const float* x, const float* y, const float* z, std::size_t n, const float* q, float lo2,
          float hi2, std::size_t* below, float* band, std::size_t* m) {
  const DL d;
  const std::size_t N = hn::Lanes(d);
  const VL qx = hn::Set(d, q[0]), qy = hn::Set(d, q[1]), qz = hn::Set(d, q[2]);
  const VL lo = hn::Set(d, lo2), hi = hn::Set(d, hi2);
  std::size_t count = 0, k = *m;
  // The last few points (n not a multiple of N) through masked loads, not a scalar loop:
  // callers pass the runs of a cell's neighbourhood (about 24 points each at 2.1M), so the tails
  // were a large share.
  for (std::size_t j = 0; j < n; j += N) {
    const bool whole = n - j >= N;
    const ML in = hn::FirstN(d, n - j);
    const VL d2 = squared_distance(load(d, x + j, whole, in), load(d, y + j, whole, in),
                                   load(d, z + j, whole, in), qx, qy, qz);
    const ML under = hn::And(hn::Lt(d2, lo), in);
    count += hn::CountTrue(d, under);
    // The band's lanes, compressed to the front; a whole vector may be stored.
    k += compress_store(d2, hn::AndNot(under, hn::And(hn::Lt(d2, hi), in)), d, band + k);
  }
  *below += count;
  *m = k;
}

// The cnt lanes sum in 32 bits (the caller keeps a call's sum below 2^32).
void Within(const float* x, const float* y, const float* z, const std::uint32_t* cnt,
            const float* lik, std::size_t n, const float* q, float r2, float lik_max,
            WithinCounts* out) {
  const DL d;
  const DLU du;
  const std::size_t N = hn::Lanes(d);
  const VL qx = hn::Set(d, q[0]), qy = hn::Set(d, q[1]), qz = hn::Set(d, q[2]);
  const VL rr = hn::Set(d, r2), lm = hn::Set(d, lik_max);
  auto sum = hn::Zero(du);
  std::size_t within = 0, below = 0;
  for (std::size_t j = 0; j < n; j += N) {  // the last few through masked loads, as Band
    const bool whole = n - j >= N;
    const ML valid = hn::FirstN(d, n - j);
    const VL d2 = squared_distance(load(d, x + j, whole, valid), load(d, y + j, whole, valid),
                                   load(d, z + j, whole, valid), qx, qy, qz);
    const ML in = hn::And(hn::Lt(d2, rr), valid);
    const auto c = load(du, cnt + j, whole, hn::RebindMask(du, valid));
    sum = hn::Add(sum, hn::IfThenElseZero(hn::RebindMask(du, in), c));
    within += hn::CountTrue(d, in);
    if (lik) below += hn::CountTrue(d, hn::And(in, hn::Le(load(d, lik + j, whole, valid), lm)));
  }
  out->sum += hn::GetLane(hn::SumOfLanes(du, sum));
  out->n += within;
  out->at_or_below += below;
}

// The squared distance from the points to the box [lo, hi]: the gaps per axis, rounded in
// float.
void NearBox(const float* x, const float* y, const float* z, const std::uint32_t* slot,
             const float* extra, std::size_t n, const float* lo, const float* hi, float r2,
             NearBoxOut* out, std::size_t* m) {
  const DL d;
  const DLU du;
  const std::size_t N = hn::Lanes(d);
  const VL lx = hn::Set(d, lo[0]), ly = hn::Set(d, lo[1]), lz = hn::Set(d, lo[2]);
  const VL hx = hn::Set(d, hi[0]), hy = hn::Set(d, hi[1]), hz = hn::Set(d, hi[2]);
  const VL rr = hn::Set(d, r2), zero = hn::Zero(d);
  std::size_t k = *m;
  // The last few points (n not a multiple of N) through masked loads, which read nothing past
  // the arrays: runs of a cell's neighbourhood are short, and a scalar tail took a fifth of the
  // time.
  for (std::size_t j = 0; j < n; j += N) {
    const bool whole = n - j >= N;
    const ML valid = hn::FirstN(d, n - j);
    const VL px = load(d, x + j, whole, valid), py = load(d, y + j, whole, valid),
             pz = load(d, z + j, whole, valid);
    const VL ex = hn::Max(hn::Max(hn::Sub(lx, px), hn::Sub(px, hx)), zero);
    const VL ey = hn::Max(hn::Max(hn::Sub(ly, py), hn::Sub(py, hy)), zero);
    const VL ez = hn::Max(hn::Max(hn::Sub(lz, pz), hn::Sub(pz, hz)), zero);
    const VL g2 = hn::Add(hn::Add(hn::Mul(ex, ex), hn::Mul(ey, ey)), hn::Mul(ez, ez));
    const ML keep = hn::And(hn::Lt(g2, rr), valid);
    if (hn::AllFalse(d, keep)) continue;
    if (slot) {
      compress_store(load(du, slot + j, whole, hn::RebindMask(du, valid)), hn::RebindMask(du, keep),
                     du, out->slot + k);
    }
    if (extra) compress_store(load(d, extra + j, whole, valid), keep, d, out->extra + k);
    compress_store(px, keep, d, out->x + k);
    compress_store(py, keep, d, out->y + k);
    k += compress_store(pz, keep, d, out->z + k);
  }
  *m = k;
}

// Points [j, e) of Within8 and Reach8 (kReach: also within scale sigma + margin), in whole
// vectors of dv (e - j a multiple of its lanes); returns the new count m. A whole vector is
// stored at m <= j (so within n); the count advances by the selected.
template <bool kReach, class DV>
HWY_INLINE std::size_t select_from(DV d, const float* x, const float* y, const float* z,
                                   const float* sigma, const std::uint32_t* slots, std::size_t j,
                                   std::size_t e, const float* origin, float r2, float scale,
                                   float margin, std::uint32_t* out, std::size_t m) {
  const hn::RebindToUnsigned<DV> du;
  const std::size_t N = hn::Lanes(d);
  const auto ox = hn::Set(d, origin[0]), oy = hn::Set(d, origin[1]), oz = hn::Set(d, origin[2]);
  const auto rr = hn::Set(d, r2), sc = hn::Set(d, scale), mg = hn::Set(d, margin);
  for (; j < e; j += N) {
    const auto d2 =
        squared_distance(hn::LoadU(d, x + j), hn::LoadU(d, y + j), hn::LoadU(d, z + j), ox, oy, oz);
    auto in = hn::Lt(d2, rr);
    if constexpr (kReach) {
      const auto reach = hn::Add(hn::Mul(sc, hn::LoadU(d, sigma + j)), mg);
      in = hn::And(in, hn::Lt(d2, hn::Mul(reach, reach)));
    }
    m += compress_store(hn::LoadU(du, slots + j), hn::RebindMask(du, in), du, out + m);
  }
  return m;
}

// n a multiple of 8 (padded): whole vectors of DL, then (with 16 lanes) one of D for the last 8.
template <bool kReach>
HWY_INLINE std::size_t select_padded(const float* x, const float* y, const float* z,
                                     const float* sigma, const std::uint32_t* slots, std::size_t n,
                                     const float* origin, float r2, float scale, float margin,
                                     std::uint32_t* out) {
  const DL dl;
  const std::size_t wide = n / hn::Lanes(dl) * hn::Lanes(dl);
  const std::size_t m =
      select_from<kReach>(dl, x, y, z, sigma, slots, 0, wide, origin, r2, scale, margin, out, 0);
  return select_from<kReach>(D(), x, y, z, sigma, slots, wide, n, origin, r2, scale, margin, out,
                             m);
}

std::size_t Within8(const float* x, const float* y, const float* z, const std::uint32_t* slots,
                    std::size_t n, const float* origin, float r2, std::uint32_t* out) {
  return select_padded<false>(x, y, z, nullptr, slots, n, origin, r2, 0.0f, 0.0f, out);
}

std::size_t Reach8(const float* x, const float* y, const float* z, const float* sigma,
                   const std::uint32_t* slots, std::size_t n, const float* origin, float r2,
                   float scale, float margin, std::uint32_t* out) {
  return select_padded<true>(x, y, z, sigma, slots, n, origin, r2, scale, margin, out);
}

// split_run: whole vectors of dv from k on, while they fit; returns where it stopped.
template <class DV>
HWY_INLINE std::size_t split_from(DV d, const float* xyz, std::size_t k, std::size_t n,
                                  std::uint32_t first, float* x, float* y, float* z,
                                  std::uint32_t* slot) {
  const hn::RebindToUnsigned<DV> du;
  const std::size_t N = hn::Lanes(d);
  for (; k + N <= n; k += N) {
    hn::Vec<DV> px, py, pz;
    hn::LoadInterleaved3(d, xyz + 3 * k, px, py, pz);
    hn::StoreU(px, d, x + k);
    hn::StoreU(py, d, y + k);
    hn::StoreU(pz, d, z + k);
    hn::StoreU(hn::Iota(du, first + static_cast<std::uint32_t>(k)), du, slot + k);
  }
  return k;
}

// Whole vectors of DL, then of D (where DL is wider), then one point at a time.
void SplitRun(const float* xyz, std::size_t n, std::uint32_t first, float* x, float* y, float* z,
              std::uint32_t* slot) {
  std::size_t k = split_from(DL(), xyz, 0, n, first, x, y, z, slot);
  k = split_from(D(), xyz, k, n, first, x, y, z, slot);
  for (; k < n; ++k) {
    x[k] = xyz[3 * k];
    y[k] = xyz[3 * k + 1];
    z[k] = xyz[3 * k + 2];
    slot[k] = first + static_cast<std::uint32_t>(k);
  }
}

const char* Target() {
  return hwy::TargetName(HWY_TARGET);
}

SelectLoops Loops() {
  SelectLoops l;
  l.band = &Band;
  l.within = &Within;
  l.near_box = &NearBox;
  return l;
}

}  // namespace HWY_NAMESPACE
}  // namespace scanclean::detail
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace scanclean::detail {

HWY_EXPORT(RankSelect);
HWY_EXPORT(BinsOf);
HWY_EXPORT(KeepBin);
HWY_EXPORT(Within8);
HWY_EXPORT(Reach8);
HWY_EXPORT(Loops);
HWY_EXPORT(SplitRun);

SelectLoops select_loops() {
  return HWY_DYNAMIC_DISPATCH(Loops)();
}

float kth_smallest_small(float* v, std::size_t n, std::size_t k) {
  float out = 0;
  if (n <= kSmallSelect && HWY_DYNAMIC_DISPATCH(RankSelect)(v, n, k, &out)) return out;
  std::nth_element(v, v + k, v + n);
  return v[k];
}

float kth_smallest_between(float* v, std::size_t n, std::size_t k, float lower, float upper) {
  constexpr std::size_t kBins = 64;
  const float scale = static_cast<float>(kBins) / (upper - lower);
  if (n <= kBins || !(upper > lower) || !(scale > 0) || !std::isfinite(scale))
    return kth_smallest_small(v, n, k);
  // The bins (BinsOf): monotone in x (a difference, a product with a positive constant, then
  // clamped truncation); NaN goes last.
  thread_local std::vector<std::uint8_t> bins;
  if (bins.size() < n + 8) bins.resize(2 * n + 8);
  HWY_DYNAMIC_DISPATCH(BinsOf)(v, n, lower, scale, bins.data());
  // Four interleaved counts, so that runs of values in one bin do not wait on each other's
  // increments.
  std::array<std::array<std::uint32_t, kBins>, 4> counts{};
  const std::uint8_t* bi = bins.data();
  std::size_t i = 0;
  for (; i + 4 <= n; i += 4) {
    ++counts[0][bi[i]];
    ++counts[1][bi[i + 1]];
    ++counts[2][bi[i + 2]];
    ++counts[3][bi[i + 3]];
  }
  for (; i < n; ++i) ++counts[0][bi[i]];
  std::array<std::uint32_t, kBins> count;
  for (std::size_t c = 0; c < kBins; ++c)
    count[c] = (counts[0][c] + counts[1][c]) + (counts[2][c] + counts[3][c]);
  std::size_t b = 0, before = 0;
  while (before + count[b] <= k) before += count[b++];
  const std::size_t m =
      HWY_DYNAMIC_DISPATCH(KeepBin)(v, bins.data(), n, static_cast<std::uint8_t>(b));
  return kth_smallest_small(v, m, k - before);
}

float kth_smallest_below(float* v, std::size_t n, std::size_t k, float upper) {
  return kth_smallest_between(v, n, k, 0.0f, upper);
}

void count_below_and_band(const float* x, const float* y, const float* z, std::size_t n,
                          const float q[3], float lo2, float hi2, std::size_t& below, float* band,
                          std::size_t& m) {
  select_loops().count_below_and_band(x, y, z, n, q, lo2, hi2, below, band, m);
}

void select_near_box(const float* x, const float* y, const float* z, const std::uint32_t* slot,
                     const float* extra, std::size_t n, const float lo[3], const float hi[3],
                     float r2, NearBoxOut out, std::size_t& m) {
  select_loops().select_near_box(x, y, z, slot, extra, n, lo, hi, r2, out, m);
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
  select_loops().count_within(x, y, z, cnt, lik, n, q, r2, lik_max, out);
}

std::size_t select_within(const float* x, const float* y, const float* z,
                          const std::uint32_t* slots, std::size_t n, const float origin[3],
                          float r2, std::uint32_t* out) {
  return HWY_DYNAMIC_DISPATCH(Within8)(x, y, z, slots, n, origin, r2, out);
}

std::size_t select_within_reach(const float* x, const float* y, const float* z, const float* sigma,
                                const std::uint32_t* slots, std::size_t n, const float origin[3],
                                float r2, float scale, float margin, std::uint32_t* out) {
  return HWY_DYNAMIC_DISPATCH(Reach8)(x, y, z, sigma, slots, n, origin, r2, scale, margin, out);
}

void split_run(const float* xyz, std::size_t n, std::uint32_t first, float* x, float* y, float* z,
               std::uint32_t* slot) {
  HWY_DYNAMIC_DISPATCH(SplitRun)(xyz, n, first, x, y, z, slot);
}

}  // namespace scanclean::detail
#endif  // HWY_ONCE

#include "candidate_eval.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

// The loops over a point's candidates are written once with Google Highway and compiled for
// every instruction set it targets on the build machine's architecture; the best one the
// processor has runs. The sums run in vectors of 8 floats (kCandidatePadding): AVX2 and AVX-512
// sum in the same order and give the same results (AVX-512 takes 16 lanes in the loops without
// sums, and forms the step's terms 16 at a time before adding them 8 at a time); 4-lane targets
// (SSE4, NEON) sum in another order.
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "candidate_eval.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace scanclean::detail {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

using D = hn::CappedTag<float, 8>;
using DI = hn::RebindToSigned<D>;
using V = hn::Vec<D>;
using B = CandidateBuffer;

constexpr float kLog2e = 1.44269504088896341f;

// The loops without sums (e_j, d_j and their minimum) take whole AVX-512 vectors (16 floats)
// where the processor has them, then one of 8 lanes for a last 8 (the padding is a multiple of
// 8): the same values in every lane. The sums stay in 8 lanes, in the same order on every
// target that has 8.
#if HWY_ARCH_X86 && HWY_TARGET <= HWY_AVX3
using DL = hn::ScalableTag<float>;
#else
using DL = D;
#endif

template <class DV>
HWY_INLINE hn::Vec<DV> field(DV d, const CandidateBuffer& b, std::size_t f, std::size_t j) {
  return hn::LoadU(d, b.f[f].data() + j);
}

// exp(a[k]) for each of K vectors, a in [-80, 0]: 2^t with t = a log2(e) = n + f,
// n = round(t), f in [-0.5, 0.5]; Cephes exp2f polynomial. The K vectors go through each
// operation side by side: their dependency chains (the polynomial's above all) then overlap,
// where one vector at a time left the processor waiting on their latency.
// The same operations lane by lane for any vector width DV.
template <std::size_t K, class DV, class VV = hn::Vec<DV>>
HWY_INLINE void vexp_n(DV d, const VV (&a)[K], VV (&r)[K]) {
  const hn::RebindToSigned<DV> di;
  using VI = hn::Vec<decltype(di)>;
  VV t[K], tr[K], f[K], p[K];
  VI n[K];
  for (std::size_t k = 0; k < K; ++k) t[k] = hn::Mul(a[k], hn::Set(d, kLog2e));
  for (std::size_t k = 0; k < K; ++k) tr[k] = hn::Add(t[k], hn::Set(d, 0.5f));
  for (std::size_t k = 0; k < K; ++k) n[k] = hn::ConvertTo(di, tr[k]);  // toward zero
  // floor: -1 where truncation rounded up
  for (std::size_t k = 0; k < K; ++k)
    n[k] = hn::Add(n[k],
                   hn::VecFromMask(di, hn::RebindMask(di, hn::Gt(hn::ConvertTo(d, n[k]), tr[k]))));
  for (std::size_t k = 0; k < K; ++k) f[k] = hn::Sub(t[k], hn::ConvertTo(d, n[k]));
  for (std::size_t k = 0; k < K; ++k)
    p[k] = hn::MulAdd(hn::Set(d, 1.535336188319500e-4f), f[k], hn::Set(d, 1.339887440266574e-3f));
  for (const float c : {9.618437357674640e-3f, 5.550332471162809e-2f, 2.402264791363012e-1f,
                        6.931472028550421e-1f, 1.0f})
    for (std::size_t k = 0; k < K; ++k) p[k] = hn::MulAdd(p[k], f[k], hn::Set(d, c));
  for (std::size_t k = 0; k < K; ++k)
    r[k] = hn::Mul(p[k], hn::BitCast(d, hn::ShiftLeft<23>(hn::Add(n[k], hn::Set(di, 127)))));
}

HWY_INLINE V vexp(D d, V a) {
  const V in[1] = {a};
  V out[1];
  vexp_n<1>(d, in, out);
  return out[0];
}

// The Mahalanobis e_j = x^T S_j^-1 x and the signed distance d_j = n_j . x of the candidates
// [j, j + N) at the point (xs, ys, zs), x taken relative to their centres.
template <class DV, class VV = hn::Vec<DV>>
HWY_INLINE void e_and_d(DV d, const CandidateBuffer& b, std::size_t j, VV xs, VV ys, VV zs, VV& e,
                        VV& dist) {
  const VV dx = hn::Sub(xs, field(d, b, B::kCx, j));
  const VV dy = hn::Sub(ys, field(d, b, B::kCy, j));
  const VV dz = hn::Sub(zs, field(d, b, B::kCz, j));
  // The multiply-adds are explicit (the file is compiled without contraction): fused where the
  // target has FMA, rounded twice where it has not.
  const VV diag = hn::MulAdd(hn::Mul(field(d, b, B::kQ22, j), dz), dz,
                             hn::MulAdd(hn::Mul(field(d, b, B::kQ11, j), dy), dy,
                                        hn::Mul(hn::Mul(field(d, b, B::kQ00, j), dx), dx)));
  const VV off = hn::MulAdd(hn::Mul(field(d, b, B::kQ12, j), dy), dz,
                            hn::MulAdd(hn::Mul(field(d, b, B::kQ02, j), dx), dz,
                                       hn::Mul(hn::Mul(field(d, b, B::kQ01, j), dx), dy)));
  e = hn::Add(diag, off);
  dist = hn::MulAdd(dz, field(d, b, B::kNz, j),
                    hn::MulAdd(dy, field(d, b, B::kNy, j), hn::Mul(dx, field(d, b, B::kNx, j))));
}

// The smallest lane of v, +inf where every lane is +inf. Highway 1.0.3's portable fallback
// (EMU128) starts its MinOfLanes from the largest finite float and returned that for a vector
// of +inf: a point no kernel kept looked kept (seen in the tests of a clang build).
template <class DV>
HWY_INLINE float min_lane(DV d, hn::Vec<DV> v) {
  const float m = hn::GetLane(hn::MinOfLanes(d, v));
#if HWY_TARGET == HWY_EMU128
  const float inf = std::numeric_limits<float>::infinity();
  if (hn::AllTrue(d, hn::Eq(v, hn::Set(d, inf)))) return inf;
#endif
  return m;
}

// Candidates [j, e) in whole vectors of dv: e_j kept where within the slab and, with
// kTruncate, below t2 (else +inf), stored with d_j; returns the smallest kept e_j (+inf if
// none).
template <bool kTruncate, class DV>
HWY_INLINE float store_e_and_d(DV d, CandidateBuffer& b, std::size_t j, std::size_t e,
                               const float* x, float t2) {
  const std::size_t N = hn::Lanes(d);
  const auto inf = hn::Set(d, std::numeric_limits<float>::infinity());
  const auto vt2 = hn::Set(d, t2);
  const auto xs = hn::Set(d, x[0]), ys = hn::Set(d, x[1]), zs = hn::Set(d, x[2]);
  float* e_out = b.f[B::kE].data();
  float* d_out = b.d.data();
  auto vmin = inf;
  for (; j < e; j += N) {
    hn::Vec<DV> ej, dist;
    e_and_d(d, b, j, xs, ys, zs, ej, dist);
    auto keep = hn::Lt(hn::Mul(dist, dist), field(d, b, B::kSlab2, j));
    if constexpr (kTruncate) keep = hn::And(hn::Lt(ej, vt2), keep);
    const auto em = hn::IfThenElse(keep, ej, inf);
    vmin = hn::Min(vmin, em);
    hn::StoreU(em, d, e_out + j);
    hn::StoreU(dist, d, d_out + j);
  }
  return min_lane(d, vmin);
}

// The padded candidates in whole vectors of DL, then of D for a last 8.
template <bool kTruncate>
HWY_INLINE float store_e_and_d(CandidateBuffer& b, const float* x, float t2) {
  const DL dl;
  const std::size_t wide = b.padded / hn::Lanes(dl) * hn::Lanes(dl);
  const float a = store_e_and_d<kTruncate>(dl, b, 0, wide, x, t2);
  return std::min(a, store_e_and_d<kTruncate>(D(), b, wide, b.padded, x, t2));
}

// The lanes of v summed in double, in lane order.
HWY_INLINE double lane_sum(D d, V v) {
  HWY_ALIGN float lanes[8];
  hn::Store(v, d, lanes);
  double sum = 0;
  for (std::size_t l = 0; l < hn::Lanes(d); ++l) sum += lanes[l];
  return sum;
}

// The step's sums (step_impl) in 8 lanes each.
struct LaneSums {
  V s, dx, dy, dz, nx, ny, nz, slab;
};

// One vector of candidates' terms of the step (from i on, weights w = exp((e_min - e_j) / 2)),
// in any vector width: the same operations lane by lane.
template <class DV, class VV = hn::Vec<DV>>
struct StepTerms {
  VV om, od, os, st, nx, ny, nz;  // omega, omega d, s omega, omega max(0, h2 - d^2), n
};
template <class DV, class VV = hn::Vec<DV>>
HWY_INLINE StepTerms<DV> step_terms(DV d, const CandidateBuffer& b, std::size_t i, VV em, VV w,
                                    VV rx, VV ry, VV rz) {
  const VV inf = hn::Set(d, std::numeric_limits<float>::infinity()), zero = hn::Zero(d);
  StepTerms<DV> t;
  t.om = hn::IfThenElseZero(hn::Lt(em, inf), hn::Mul(field(d, b, B::kW, i), w));
  const VV dist = hn::LoadU(d, b.d.data() + i);
  t.nx = field(d, b, B::kNx, i);
  t.ny = field(d, b, B::kNy, i);
  t.nz = field(d, b, B::kNz, i);
  t.od = hn::Mul(t.om, dist);
  const VV s = hn::MulAdd(t.nz, rz, hn::MulAdd(t.ny, ry, hn::Mul(t.nx, rx)));
  t.os = hn::IfThenElse(hn::Lt(s, zero), hn::Neg(t.om), t.om);        // s_j omega_j
  const VV slab = hn::NegMulAdd(dist, dist, field(d, b, B::kH2, i));  // h2_j - d_j^2
  t.st = hn::IfThenElseZero(hn::Gt(slab, zero), hn::Mul(t.om, slab));
  return t;
}

// Adds 8 candidates' terms to the sums.
HWY_INLINE void accumulate(const StepTerms<D>& t, LaneSums& a) {
  a.slab = hn::Add(a.slab, t.st);
  a.s = hn::Add(a.s, t.om);
  a.dx = hn::MulAdd(t.od, t.nx, a.dx);
  a.dy = hn::MulAdd(t.od, t.ny, a.dy);
  a.dz = hn::MulAdd(t.od, t.nz, a.dz);
  a.nx = hn::MulAdd(t.os, t.nx, a.nx);
  a.ny = hn::MulAdd(t.os, t.ny, a.ny);
  a.nz = hn::MulAdd(t.os, t.nz, a.nz);
}

// Adds the terms of the K vectors of candidates from j on to the sums, one vector after the
// other (the same operations in the same order for any K; K > 1 overlaps their weights' exp).
template <std::size_t K>
HWY_INLINE void add_step_terms(D d, const CandidateBuffer& b, std::size_t j, V emv, V rx, V ry,
                               V rz, LaneSums& a) {
  const std::size_t N = hn::Lanes(d);
  const V floor = hn::Set(d, -80.0f), half = hn::Set(d, 0.5f);
  const float* e_in = b.f[B::kE].data() + j;
  V em[K], w[K];
  for (std::size_t k = 0; k < K; ++k) {
    em[k] = hn::LoadU(d, e_in + k * N);
    w[k] = hn::Max(hn::Mul(hn::Sub(emv, em[k]), half), floor);
  }
  vexp_n<K>(d, w, w);
  for (std::size_t k = 0; k < K; ++k)
    accumulate(step_terms(d, b, j + k * N, em[k], w[k], rx, ry, rz), a);
}

#if HWY_ARCH_X86 && HWY_TARGET <= HWY_AVX3
// add_step_terms<2> with 16-lane vectors: the weights and each candidate's terms are formed in
// one vector (the same operations lane by lane, half as many instructions), and each sum then
// takes the low 8 lanes and the high 8 in turn, as add_step_terms<2> adds its two vectors: the
// same sums bit for bit.
HWY_INLINE void add_step_terms_16(const CandidateBuffer& b, std::size_t j, float emin,
                                  const float* nref, LaneSums& a) {
  const hn::Full512<float> dw;
  const D d;
  using VW = hn::Vec<decltype(dw)>;
  const VW em = hn::LoadU(dw, b.f[B::kE].data() + j);
  VW w[1] = {
      hn::Max(hn::Mul(hn::Sub(hn::Set(dw, emin), em), hn::Set(dw, 0.5f)), hn::Set(dw, -80.0f))};
  vexp_n<1>(dw, w, w);
  const auto t = step_terms(dw, b, j, em, w[0], hn::Set(dw, nref[0]), hn::Set(dw, nref[1]),
                            hn::Set(dw, nref[2]));
  auto half = [&](auto part) {
    return StepTerms<D>{part(t.om), part(t.od), part(t.os), part(t.st),
                        part(t.nx), part(t.ny), part(t.nz)};
  };
  accumulate(half([&](VW v) { return hn::LowerHalf(d, v); }), a);
  accumulate(half([&](VW v) { return hn::UpperHalf(d, v); }), a);
}
#endif

// kReuse: e_j (slab-masked) and d_j are already in the buffer, from min_mahalanobis at the same
// x; only the truncation mask is applied (the same values as computing them again).
template <bool kReuse>
HWY_INLINE bool step_impl(CandidateBuffer& b, const float* x, const float* nref, float t2,
                          StepSums* out) {
  const D d;
  const std::size_t N = hn::Lanes(d);
  const V inf = hn::Set(d, std::numeric_limits<float>::infinity()), zero = hn::Zero(d);
  const V vt2 = hn::Set(d, t2);
  V vmin = inf;
  const std::size_t n = b.padded;
  float* e_out = b.f[B::kE].data();
  if constexpr (kReuse) {
    for (std::size_t j = 0; j < n; j += N) {
      const V e = hn::LoadU(d, e_out + j);
      const V em = hn::IfThenElse(hn::Lt(e, vt2), e, inf);
      vmin = hn::Min(vmin, em);
      hn::StoreU(em, d, e_out + j);
    }
  }
  const float emin = kReuse ? min_lane(d, vmin) : store_e_and_d<true>(b, x, t2);
  if (!(emin < std::numeric_limits<float>::infinity())) return false;
  LaneSums a{zero, zero, zero, zero, zero, zero, zero, zero};
  const V emv = hn::Set(d, emin);
  const V rx = hn::Set(d, nref[0]), ry = hn::Set(d, nref[1]), rz = hn::Set(d, nref[2]);
  std::size_t j = 0;
#if HWY_ARCH_X86 && HWY_TARGET <= HWY_AVX3
  for (; j + 2 * N <= n; j += 2 * N) add_step_terms_16(b, j, emin, nref, a);
#else
  for (; j + 2 * N <= n; j += 2 * N) add_step_terms<2>(d, b, j, emv, rx, ry, rz, a);
#endif
  for (; j < n; j += N) add_step_terms<1>(d, b, j, emv, rx, ry, rz, a);
  StepSums r;
  r.e_min = emin;
  r.s = lane_sum(d, a.s);
  r.dn[0] = lane_sum(d, a.dx);
  r.dn[1] = lane_sum(d, a.dy);
  r.dn[2] = lane_sum(d, a.dz);
  r.n[0] = lane_sum(d, a.nx);
  r.n[1] = lane_sum(d, a.ny);
  r.n[2] = lane_sum(d, a.nz);
  r.slab_sum = lane_sum(d, a.slab);
  *out = r;
  return true;
}

bool Step(CandidateBuffer& b, const float* x, const float* nref, float t2, StepSums* out) {
  return step_impl<false>(b, x, nref, t2, out);
}
bool StepReuse(CandidateBuffer& b, const float* nref, float t2, StepSums* out) {
  return step_impl<true>(b, nullptr, nref, t2, out);
}

// The slab-masked e_j (not truncated) and d_j, and the smallest e_j.
float MinE(CandidateBuffer& b, const float* x) {
  return store_e_and_d<false>(b, x, 0.0f);
}

double Likelihood(CandidateBuffer& b, const float* x, float t2) {
  const D d;
  const std::size_t N = hn::Lanes(d);
  const V xs = hn::Set(d, x[0]), ys = hn::Set(d, x[1]), zs = hn::Set(d, x[2]);
  const V vt2 = hn::Set(d, t2), zero = hn::Zero(d), floor = hn::Set(d, -80.0f);
  V acc = zero;
  for (std::size_t j = 0; j < b.padded; j += N) {
    V e, dist;
    e_and_d(d, b, j, xs, ys, zs, e, dist);
    const V slab = hn::NegMulAdd(dist, dist, field(d, b, B::kH2, j));
    const auto keep = hn::And(hn::Lt(e, vt2), hn::Gt(slab, zero));
    const V a = hn::Max(hn::Mul(e, hn::Set(d, -0.5f)), floor);
    const V term = hn::Mul(hn::Mul(field(d, b, B::kW, j), vexp(d, a)), slab);
    acc = hn::Add(acc, hn::IfThenElseZero(keep, term));
  }
  return lane_sum(d, acc);
}

// The first candidate j < n (n a multiple of the lanes, the padding's e_j never equal) whose
// e_j is e; n - 1 if none is.
std::size_t FirstWithE(const CandidateBuffer& b, float e, std::size_t n) {
  const D d;
  const std::size_t N = hn::Lanes(d);
  const V ve = hn::Set(d, e);
  const float* es = b.f[B::kE].data();
  for (std::size_t j = 0; j < n; j += N) {
    const intptr_t l = hn::FindFirstTrue(d, hn::Eq(hn::LoadU(d, es + j), ve));
    if (l >= 0) return std::min(j + static_cast<std::size_t>(l), b.count - 1);
  }
  return b.count - 1;
}

float FastExp(float a) {
  const D d;
  return hn::GetLane(vexp(d, hn::Set(d, a)));
}

#if HWY_ARCH_X86 && (HWY_TARGET <= HWY_AVX3 || HWY_TARGET == HWY_AVX2)
// The first two rounds of the transposition of 8 records r[i] (a vector each, or a half each):
// records interleaved in pairs within each block of 4 lanes, then pairs of those, which
// leaves in block b of u[k] field 4 b + k of records 0-3 (of u[k + 4]: records 4-7).
template <class DV, class VV = hn::Vec<DV>>
HWY_INLINE void interleave_records(DV d, const VV (&r)[8], VV (&u)[8]) {
  const hn::Repartition<std::uint64_t, DV> d64;
  auto lower64 = [&](VV x, VV y) {
    return hn::BitCast(d, hn::InterleaveLower(d64, hn::BitCast(d64, x), hn::BitCast(d64, y)));
  };
  auto upper64 = [&](VV x, VV y) {
    return hn::BitCast(d, hn::InterleaveUpper(d64, hn::BitCast(d64, x), hn::BitCast(d64, y)));
  };
  VV t[8];
  for (std::size_t i = 0; i < 8; i += 2) {
    t[i] = hn::InterleaveLower(d, r[i], r[i + 1]);
    t[i + 1] = hn::InterleaveUpper(d, r[i], r[i + 1]);
  }
  for (std::size_t i = 0; i < 8; i += 4) {
    u[i] = lower64(t[i], t[i + 2]);
    u[i + 1] = upper64(t[i], t[i + 2]);
    u[i + 2] = lower64(t[i + 1], t[i + 3]);
    u[i + 3] = upper64(t[i + 1], t[i + 3]);
  }
}
#endif

#if HWY_ARCH_X86 && HWY_TARGET <= HWY_AVX3
// The transposition of 8 records (16 floats, one vector each) into the buffer's arrays, in
// three rounds of shuffles: the two of interleave_records, then the blocks of u[k] and u[k + 4]
// paired, so that each half of a vector holds one field of all 8 records. About 4 shuffles a
// record where the AVX2 transposition takes 6; the records are aligned to their cache line
// (KernelRecord), so each is one aligned load. A whole group loads its records without the
// last group's repetition and copies its 8 slots as one vector (about a tenth of the append's
// cpu-clock samples less than one slot at a time).
void AppendRecords(CandidateBuffer& b, const KernelRecord* records, const std::uint32_t* slots,
                   std::size_t n, const float* origin, float slab2) {
  const hn::Full512<float> d16;
  const hn::Full256<float> d8;
  const hn::Full256<std::uint32_t> du8;
  using V16 = hn::Vec<decltype(d16)>;
  const auto ox = hn::Set(d8, origin[0]), oy = hn::Set(d8, origin[1]), oz = hn::Set(d8, origin[2]),
             vslab2 = hn::Set(d8, slab2);
  // The arrays, read once: through the stores the compiler could not tell that they stay put.
  float* out[B::kFields];
  for (std::size_t f = 0; f < B::kFields; ++f) out[f] = b.f[f].data();
  std::uint32_t* slot_out = b.slot.data();
  for (std::size_t k = 0; k < n; k += 8) {
    // The last group of fewer than 8 repeats its last record; the lanes past it are written
    // (append_records reserved room for them) but not counted.
    const std::size_t j = b.count, m = std::min<std::size_t>(8, n - k);
    V16 r[8];
    if (m == 8) {
      for (std::size_t i = 0; i < 8; ++i) r[i] = hn::Load(d16, records[slots[k + i]].f);
    } else {
      for (std::size_t i = 0; i < 8; ++i)
        r[i] = hn::Load(d16, records[slots[k + std::min(i, m - 1)]].f);
    }
    V16 u[8];
    interleave_records(d16, r, u);
    V16 lo[4], hi[4];  // lo[k]: fields k and 8 + k; hi[k]: fields 4 + k and 12 + k
    for (std::size_t f = 0; f < 4; ++f) {
      lo[f] = hn::OddEvenBlocks(hn::SwapAdjacentBlocks(u[f + 4]), u[f]);
      hi[f] = hn::OddEvenBlocks(u[f + 4], hn::SwapAdjacentBlocks(u[f]));
    }
    auto put = [&](std::size_t field, hn::Vec<decltype(d8)> v) {
      hn::StoreU(v, d8, out[field] + j);
    };
    put(B::kCx, hn::Sub(hn::LowerHalf(d8, lo[0]), ox));
    put(B::kCy, hn::Sub(hn::LowerHalf(d8, lo[1]), oy));
    put(B::kCz, hn::Sub(hn::LowerHalf(d8, lo[2]), oz));
    put(B::kQ00, hn::LowerHalf(d8, lo[3]));
    for (std::size_t f = 0; f < 4; ++f) {
      put(B::kQ11 + f, hn::LowerHalf(d8, hi[f]));  // fields 4-7: Q11 Q22 Q01 Q02
      put(B::kQ12 + f, hn::UpperHalf(d8, lo[f]));  // fields 8-11: Q12 and the normal
    }
    const auto h2 = hn::UpperHalf(d8, hi[0]);  // record field 12
    put(B::kSlab2, hn::Mul(h2, vslab2));
    put(B::kH2, h2);
    put(B::kW, hn::UpperHalf(d8, hi[1]));  // record field 13
    if (m == 8)
      hn::StoreU(hn::LoadU(du8, slots + k), du8, slot_out + j);
    else
      for (std::size_t i = 0; i < m; ++i) slot_out[j + i] = slots[k + i];
    b.count += m;
  }
}
#elif HWY_ARCH_X86 && HWY_TARGET == HWY_AVX2
// The transposition of 8 records into the buffer's arrays in 8-float vectors, each record's
// two halves (fields 0-7, 8-15) one after the other, in three rounds: the two of
// interleave_records, then the blocks of 4 of u[k] and u[k + 4] paired, which leaves one field
// of all 8 records in each vector. A last group of fewer than 8 is appended one record at a
// time (AVX-512's way here, a short group's last record repeated and the arrays' pointers
// read once, took about a quarter longer).
void AppendRecords(CandidateBuffer& b, const KernelRecord* records, const std::uint32_t* slots,
                   std::size_t n, const float* origin, float slab2) {
  const hn::Full256<float> d8;
  const hn::Full256<std::uint32_t> du8;
  using V8 = hn::Vec<decltype(d8)>;
  const V8 org[3] = {hn::Set(d8, origin[0]), hn::Set(d8, origin[1]), hn::Set(d8, origin[2])};
  const V8 vslab2 = hn::Set(d8, slab2);
  std::size_t k = 0;
  for (; k + 8 <= n; k += 8) {
    const std::size_t j = b.count;
    for (std::size_t half = 0; half < 2; ++half) {
      V8 r[8];
      for (std::size_t i = 0; i < 8; ++i) r[i] = hn::Load(d8, records[slots[k + i]].f + 8 * half);
      V8 u[8];
      interleave_records(d8, r, u);
      V8 c[8];  // c[f]: field 8 half + f of the 8 records
      for (std::size_t f = 0; f < 4; ++f) {
        c[f] = hn::ConcatLowerLower(d8, u[f + 4], u[f]);
        c[f + 4] = hn::ConcatUpperUpper(d8, u[f + 4], u[f]);
      }
      auto put = [&](std::size_t field, V8 v) { hn::StoreU(v, d8, b.f[field].data() + j); };
      if (half == 0) {
        for (std::size_t f = 0; f < 3; ++f) put(B::kCx + f, hn::Sub(c[f], org[f]));
        for (std::size_t f = 3; f < 8; ++f) put(f, c[f]);  // Q00 Q11 Q22 Q01 Q02
      } else {
        for (std::size_t f = 0; f < 4; ++f) put(B::kQ12 + f, c[f]);  // Q12 and the normal
        put(B::kSlab2, hn::Mul(c[4], vslab2));                       // record field 12: h^2
        put(B::kH2, c[4]);
        put(B::kW, c[5]);  // record field 13
      }
    }
    hn::StoreU(hn::LoadU(du8, slots + k), du8, b.slot.data() + j);
    b.count += 8;
  }
  for (; k < n; ++k) b.push_record(slots[k], records[slots[k]], origin, slab2);
}
#else
void AppendRecords(CandidateBuffer& b, const KernelRecord* records, const std::uint32_t* slots,
                   std::size_t n, const float* origin, float slab2) {
  for (std::size_t k = 0; k < n; ++k) b.push_record(slots[k], records[slots[k]], origin, slab2);
}
#endif

}  // namespace HWY_NAMESPACE
}  // namespace scanclean::detail
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace scanclean::detail {

void CandidateBuffer::reserve(std::size_t n) {
  const std::size_t cap = n + 2 * kCandidatePadding;
  if (capacity_ >= cap) return;
  // The 17 arrays lie in one block, 64-byte aligned, each starting 192 bytes further into a
  // 4 KiB page than the one before. Allocated apart, they started wherever the allocator put
  // them: where two started at the same offset within a page, the processor took the loads from
  // one for loads after stores to the other (4K aliasing) and waited, and the same run took up
  // to twice as long in the append from one start of the program to the next.
  constexpr std::size_t kPage = 1024, kShift = 48, kAlign = 16;  // floats
  const std::size_t stride = (cap + kPage - 1) / kPage * kPage + kShift;
  std::vector<float> block(stride * (kFields + 1) + kAlign);
  const std::size_t misalign =
      reinterpret_cast<std::uintptr_t>(block.data()) / sizeof(float) % kAlign;
  float* base = block.data() + (kAlign - misalign) % kAlign;
  CandidateArray* arrays[kFields + 1];
  for (std::size_t k = 0; k < kFields; ++k) arrays[k] = &f[k];
  arrays[kFields] = &d;
  for (std::size_t k = 0; k <= kFields; ++k) {
    float* p = base + k * stride;
    if (capacity_ > 0) std::copy(arrays[k]->p_, arrays[k]->p_ + capacity_, p);
    arrays[k]->p_ = p;
  }
  block_.swap(block);
  capacity_ = cap;
  slot.resize(cap);
}

void CandidateBuffer::finish() {
  reserve(count);
  padded = (count + kCandidatePadding - 1) / kCandidatePadding * kCandidatePadding;
  // A whole block of kCandidatePadding entries from count on in each array (reserve left room
  // for it), written in one go: the entries past padded are never read.
  for (std::size_t k = 0; k < kFields; ++k)
    std::fill_n(f[k].data() + count, kCandidatePadding, 0.0f);
  std::fill_n(f[kSlab2].data() + count, kCandidatePadding, -1.0f);  // never kept
}

HWY_EXPORT(Step);
HWY_EXPORT(StepReuse);
HWY_EXPORT(MinE);
HWY_EXPORT(Likelihood);
HWY_EXPORT(FastExp);
HWY_EXPORT(FirstWithE);
HWY_EXPORT(AppendRecords);

double StepSums::likelihood() const {
  return std::exp(-0.5 * static_cast<double>(e_min)) * slab_sum;
}

bool step_sums(CandidateBuffer& buffer, const float x[3], const float nref[3], float t2,
               StepSums& out) {
  return HWY_DYNAMIC_DISPATCH(Step)(buffer, x, nref, t2, &out);
}

bool step_sums_after_min_mahalanobis(CandidateBuffer& buffer, const float nref[3], float t2,
                                     StepSums& out) {
  return HWY_DYNAMIC_DISPATCH(StepReuse)(buffer, nref, t2, &out);
}

float min_mahalanobis(CandidateBuffer& buffer, const float x[3]) {
  return HWY_DYNAMIC_DISPATCH(MinE)(buffer, x);
}

double likelihood(CandidateBuffer& buffer, const float x[3], float t2) {
  return HWY_DYNAMIC_DISPATCH(Likelihood)(buffer, x, t2);
}

void append_records(CandidateBuffer& buffer, const KernelRecord* records,
                    const std::uint32_t* slots, std::size_t n, const float origin[3], float slab2) {
  buffer.reserve(buffer.count + n);
  HWY_DYNAMIC_DISPATCH(AppendRecords)(buffer, records, slots, n, origin, slab2);
}

float fast_exp(float a) {
  return HWY_DYNAMIC_DISPATCH(FastExp)(a);
}

std::size_t first_candidate_with_e(const CandidateBuffer& buffer, float e) {
  if (buffer.count == 0) return 0;
  return HWY_DYNAMIC_DISPATCH(FirstWithE)(buffer, e, buffer.padded);
}

}  // namespace scanclean::detail
#endif  // HWY_ONCE

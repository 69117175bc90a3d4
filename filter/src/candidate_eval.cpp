#include "candidate_eval.h"

#include <immintrin.h>

#include <cmath>
#include <cstring>
#include <limits>

// The 8-wide helpers below return vectors by value; they are always inlined into functions
// compiled for AVX2 (see step_avx2), so the ABI note GCC gives for them does not apply.
#pragma GCC diagnostic ignored "-Wpsabi"

namespace scanclean::detail {

void CandidateBuffer::reserve(std::size_t n) {
  const std::size_t cap = n + 2 * kCandidatePadding;
  if (f[0].size() >= cap) return;
  for (auto& a : f) a.resize(cap);
  d.resize(cap);
  slot.resize(cap);
}

void CandidateBuffer::finish() {
  reserve(count);
  padded = (count + kCandidatePadding - 1) / kCandidatePadding * kCandidatePadding;
  for (std::size_t j = count; j < padded; ++j) {
    for (std::size_t k = 0; k < kFields; ++k) f[k][j] = 0;
    f[kSlab2][j] = -1;  // never kept
  }
}

namespace {

constexpr float kLog2e = 1.44269504088896341f;

template <class V, class VI>
[[gnu::always_inline]] inline V load(const float* p) {
  V v;
  std::memcpy(&v, p, sizeof(V));
  return v;
}

// Unaligned float vectors for the stores: stored as floats (not through memcpy, which may
// alias anything), so that the compiler keeps the buffer's array pointers in registers across
// the stores instead of loading them again at every iteration.
typedef float V4u __attribute__((vector_size(16), aligned(4)));
typedef float V8u __attribute__((vector_size(32), aligned(4)));
template <class V>
[[gnu::always_inline]] inline void store(float* p, V v) {
  if constexpr (sizeof(V) == 32)
    *reinterpret_cast<V8u*>(p) = v;
  else
    *reinterpret_cast<V4u*>(p) = v;
}

template <class V, class VI>
[[gnu::always_inline]] inline V vexp(V a) {
  // 2^t with t = a log2(e) = n + f, n = round(t), f in [-0.5, 0.5]; Cephes exp2f polynomial.
  V t = a * kLog2e;
  V tr = t + 0.5f;
  VI n = __builtin_convertvector(tr, VI);  // toward zero
  V nf = __builtin_convertvector(n, V);
  n += (nf > tr);  // floor: -1 where truncation rounded up
  nf = __builtin_convertvector(n, V);
  const V f = t - nf;
  V p = 1.535336188319500e-4f * f + 1.339887440266574e-3f;
  p = p * f + 9.618437357674640e-3f;
  p = p * f + 5.550332471162809e-2f;
  p = p * f + 2.402264791363012e-1f;
  p = p * f + 6.931472028550421e-1f;
  p = p * f + 1.0f;
  VI bits = (n + 127) << 23;
  V scale;
  std::memcpy(&scale, &bits, sizeof(V));
  return p * scale;
}

// The Mahalanobis e_j = x^T S_j^-1 x and the signed distance d_j = n_j . x of the candidates
// [j, j + W) at the point (xs, ys, zs), x taken relative to their centres.
template <class V, class VI>
[[gnu::always_inline]] inline void e_and_d(const CandidateBuffer& b, std::size_t j, V xs, V ys,
                                           V zs, V& e, V& d) {
  const V dx = xs - load<V, VI>(&b.f[CandidateBuffer::kCx][j]);
  const V dy = ys - load<V, VI>(&b.f[CandidateBuffer::kCy][j]);
  const V dz = zs - load<V, VI>(&b.f[CandidateBuffer::kCz][j]);
  e = load<V, VI>(&b.f[CandidateBuffer::kQ00][j]) * dx * dx +
      load<V, VI>(&b.f[CandidateBuffer::kQ11][j]) * dy * dy +
      load<V, VI>(&b.f[CandidateBuffer::kQ22][j]) * dz * dz +
      (load<V, VI>(&b.f[CandidateBuffer::kQ01][j]) * dx * dy +
       load<V, VI>(&b.f[CandidateBuffer::kQ02][j]) * dx * dz +
       load<V, VI>(&b.f[CandidateBuffer::kQ12][j]) * dy * dz);
  d = dx * load<V, VI>(&b.f[CandidateBuffer::kNx][j]) +
      dy * load<V, VI>(&b.f[CandidateBuffer::kNy][j]) +
      dz * load<V, VI>(&b.f[CandidateBuffer::kNz][j]);
}

// kReuse: e_j (slab-masked) and d_j are already in the buffer, from min_mahalanobis at the same
// x; only the truncation mask is applied (the same values as computing them again).
template <class V, class VI, bool kReuse>
[[gnu::always_inline]] inline bool step_impl(CandidateBuffer& b, const float x[3],
                                             const float nref[3], float t2, StepSums& out) {
  constexpr int W = sizeof(V) / sizeof(float);
  const float inf = std::numeric_limits<float>::infinity();
  V vmin = V{} + inf;
  const std::size_t n = b.padded;
  float* e_out = b.f[CandidateBuffer::kE].data();
  float* d_out = b.d.data();
  if constexpr (kReuse) {
    for (std::size_t j = 0; j < n; j += W) {
      const V e = load<V, VI>(e_out + j);
      const V em = e < t2 ? e : V{} + inf;
      vmin = em < vmin ? em : vmin;
      store(e_out + j, em);
    }
  } else {
    const V xs = V{} + x[0], ys = V{} + x[1], zs = V{} + x[2];
    for (std::size_t j = 0; j < n; j += W) {
      V e, d;
      e_and_d<V, VI>(b, j, xs, ys, zs, e, d);
      const VI keep = (e < t2) & (d * d < load<V, VI>(&b.f[CandidateBuffer::kSlab2][j]));
      const V em = keep ? e : V{} + inf;
      vmin = em < vmin ? em : vmin;
      store(e_out + j, em);
      store(d_out + j, d);
    }
  }
  float emin = inf;
  for (int l = 0; l < W; ++l) emin = std::min(emin, vmin[l]);
  if (!(emin < inf)) return false;
  V as{}, adx{}, ady{}, adz{}, anx{}, any{}, anz{}, al{};
  const V emv = V{} + emin;
  const V rx = V{} + nref[0], ry = V{} + nref[1], rz = V{} + nref[2];
  for (std::size_t j = 0; j < n; j += W) {
    const V em = load<V, VI>(e_out + j);
    const VI kept = em < inf;
    V a = (emv - em) * 0.5f;
    a = a < -80.0f ? V{} - 80.0f : a;
    V om = load<V, VI>(&b.f[CandidateBuffer::kW][j]) * vexp<V, VI>(a);
    om = kept ? om : V{};
    const V d = load<V, VI>(d_out + j);
    const V nx = load<V, VI>(&b.f[CandidateBuffer::kNx][j]);
    const V ny = load<V, VI>(&b.f[CandidateBuffer::kNy][j]);
    const V nz = load<V, VI>(&b.f[CandidateBuffer::kNz][j]);
    const V od = om * d;
    const V os = (nx * rx + ny * ry + nz * rz) < 0.0f ? -om : om;  // s_j omega_j
    const V slab = load<V, VI>(&b.f[CandidateBuffer::kH2][j]) - d * d;
    al += slab > 0.0f ? om * slab : V{};
    as += om;
    adx += od * nx;
    ady += od * ny;
    adz += od * nz;
    anx += os * nx;
    any += os * ny;
    anz += os * nz;
  }
  out = StepSums{};
  out.e_min = emin;
  for (int l = 0; l < W; ++l) {
    out.s += as[l];
    out.dn[0] += adx[l];
    out.dn[1] += ady[l];
    out.dn[2] += adz[l];
    out.n[0] += anx[l];
    out.n[1] += any[l];
    out.n[2] += anz[l];
    out.slab_sum += al[l];
  }
  return true;
}

template <class V, class VI>
[[gnu::always_inline]] inline float min_e_impl(CandidateBuffer& b, const float x[3]) {
  constexpr int W = sizeof(V) / sizeof(float);
  const float inf = std::numeric_limits<float>::infinity();
  const V xs = V{} + x[0], ys = V{} + x[1], zs = V{} + x[2];
  float* e_out = b.f[CandidateBuffer::kE].data();
  float* d_out = b.d.data();
  V vmin = V{} + inf;
  for (std::size_t j = 0; j < b.padded; j += W) {
    V e, d;
    e_and_d<V, VI>(b, j, xs, ys, zs, e, d);
    const VI keep = d * d < load<V, VI>(&b.f[CandidateBuffer::kSlab2][j]);
    const V em = keep ? e : V{} + inf;
    store(e_out + j, em);
    store(d_out + j, d);
    vmin = em < vmin ? em : vmin;
  }
  float emin = inf;
  for (int l = 0; l < W; ++l) emin = std::min(emin, vmin[l]);
  return emin;
}

template <class V, class VI>
[[gnu::always_inline]] inline double likelihood_impl(CandidateBuffer& b, const float x[3],
                                                     float t2) {
  constexpr int W = sizeof(V) / sizeof(float);
  const V xs = V{} + x[0], ys = V{} + x[1], zs = V{} + x[2];
  V acc{};
  for (std::size_t j = 0; j < b.padded; j += W) {
    V e, d;
    e_and_d<V, VI>(b, j, xs, ys, zs, e, d);
    const V slab = load<V, VI>(&b.f[CandidateBuffer::kH2][j]) - d * d;
    const VI keep = (e < t2) & (slab > 0.0f);
    V a = e * -0.5f;
    a = a < -80.0f ? V{} - 80.0f : a;
    const V term = load<V, VI>(&b.f[CandidateBuffer::kW][j]) * vexp<V, VI>(a) * slab;
    acc += keep ? term : V{};
  }
  double sum = 0;
  for (int l = 0; l < W; ++l) sum += acc[l];
  return sum;
}

typedef float V4 __attribute__((vector_size(16)));
typedef int VI4 __attribute__((vector_size(16)));
typedef float V8 __attribute__((vector_size(32)));
typedef int VI8 __attribute__((vector_size(32)));

[[gnu::target("avx2,fma")]] bool step_avx2(CandidateBuffer& b, const float x[3],
                                           const float nref[3], float t2, StepSums& out) {
  return step_impl<V8, VI8, false>(b, x, nref, t2, out);
}
[[gnu::target("avx2,fma")]] bool step_reuse_avx2(CandidateBuffer& b, const float nref[3], float t2,
                                                 StepSums& out) {
  return step_impl<V8, VI8, true>(b, nullptr, nref, t2, out);
}
[[gnu::target("avx2,fma")]] double likelihood_avx2(CandidateBuffer& b, const float x[3], float t2) {
  return likelihood_impl<V8, VI8>(b, x, t2);
}
[[gnu::target("avx2,fma")]] float min_e_avx2(CandidateBuffer& b, const float x[3]) {
  return min_e_impl<V8, VI8>(b, x);
}
float min_e_sse(CandidateBuffer& b, const float x[3]) {
  return min_e_impl<V4, VI4>(b, x);
}
bool step_sse(CandidateBuffer& b, const float x[3], const float nref[3], float t2, StepSums& out) {
  return step_impl<V4, VI4, false>(b, x, nref, t2, out);
}
bool step_reuse_sse(CandidateBuffer& b, const float nref[3], float t2, StepSums& out) {
  return step_impl<V4, VI4, true>(b, nullptr, nref, t2, out);
}
double likelihood_sse(CandidateBuffer& b, const float x[3], float t2) {
  return likelihood_impl<V4, VI4>(b, x, t2);
}

[[gnu::target("avx2,fma")]] void append_avx2(CandidateBuffer& b, const KernelRecord* records,
                                             const std::uint32_t* slots, std::size_t n,
                                             const float origin[3], float slab2) {
  std::size_t k = 0;
  for (; k + 8 <= n; k += 8) {
    const std::size_t j = b.count;
    for (int half = 0; half < 2; ++half) {
      __m256 r[8];
      for (int i = 0; i < 8; ++i) r[i] = _mm256_loadu_ps(records[slots[k + i]].f + 8 * half);
      const __m256 t0 = _mm256_unpacklo_ps(r[0], r[1]), t1 = _mm256_unpackhi_ps(r[0], r[1]);
      const __m256 t2 = _mm256_unpacklo_ps(r[2], r[3]), t3 = _mm256_unpackhi_ps(r[2], r[3]);
      const __m256 t4 = _mm256_unpacklo_ps(r[4], r[5]), t5 = _mm256_unpackhi_ps(r[4], r[5]);
      const __m256 t6 = _mm256_unpacklo_ps(r[6], r[7]), t7 = _mm256_unpackhi_ps(r[6], r[7]);
      const __m256 u0 = _mm256_shuffle_ps(t0, t2, 0x44), u1 = _mm256_shuffle_ps(t0, t2, 0xEE);
      const __m256 u2 = _mm256_shuffle_ps(t1, t3, 0x44), u3 = _mm256_shuffle_ps(t1, t3, 0xEE);
      const __m256 u4 = _mm256_shuffle_ps(t4, t6, 0x44), u5 = _mm256_shuffle_ps(t4, t6, 0xEE);
      const __m256 u6 = _mm256_shuffle_ps(t5, t7, 0x44), u7 = _mm256_shuffle_ps(t5, t7, 0xEE);
      __m256 c[8];
      c[0] = _mm256_permute2f128_ps(u0, u4, 0x20);
      c[1] = _mm256_permute2f128_ps(u1, u5, 0x20);
      c[2] = _mm256_permute2f128_ps(u2, u6, 0x20);
      c[3] = _mm256_permute2f128_ps(u3, u7, 0x20);
      c[4] = _mm256_permute2f128_ps(u0, u4, 0x31);
      c[5] = _mm256_permute2f128_ps(u1, u5, 0x31);
      c[6] = _mm256_permute2f128_ps(u2, u6, 0x31);
      c[7] = _mm256_permute2f128_ps(u3, u7, 0x31);
      if (half == 0) {
        for (int f = 0; f < 3; ++f)
          _mm256_storeu_ps(&b.f[f][j], _mm256_sub_ps(c[f], _mm256_set1_ps(origin[f])));
        for (int f = 3; f < 8; ++f) _mm256_storeu_ps(&b.f[f][j], c[f]);
      } else {
        for (int f = 0; f < 4; ++f) _mm256_storeu_ps(&b.f[8 + f][j], c[f]);  // q12 n
        _mm256_storeu_ps(&b.f[CandidateBuffer::kSlab2][j],
                         _mm256_mul_ps(c[4], _mm256_set1_ps(slab2)));
        _mm256_storeu_ps(&b.f[CandidateBuffer::kH2][j], c[4]);
        _mm256_storeu_ps(&b.f[CandidateBuffer::kW][j], c[5]);
      }
    }
    for (int i = 0; i < 8; ++i) b.slot[j + i] = slots[k + i];
    b.count += 8;
  }
  for (; k < n; ++k) b.push_record(slots[k], records[slots[k]], origin, slab2);
}

bool have_avx2() {
  static const bool yes = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  return yes;
}

}  // namespace

double StepSums::likelihood() const {
  return std::exp(-0.5 * static_cast<double>(e_min)) * slab_sum;
}

bool step_sums(CandidateBuffer& buffer, const float x[3], const float nref[3], float t2,
               StepSums& out) {
  return have_avx2() ? step_avx2(buffer, x, nref, t2, out) : step_sse(buffer, x, nref, t2, out);
}

bool step_sums_after_min_mahalanobis(CandidateBuffer& buffer, const float nref[3], float t2,
                                     StepSums& out) {
  return have_avx2() ? step_reuse_avx2(buffer, nref, t2, out)
                     : step_reuse_sse(buffer, nref, t2, out);
}

float min_mahalanobis(CandidateBuffer& buffer, const float x[3]) {
  return have_avx2() ? min_e_avx2(buffer, x) : min_e_sse(buffer, x);
}

double likelihood(CandidateBuffer& buffer, const float x[3], float t2) {
  return have_avx2() ? likelihood_avx2(buffer, x, t2) : likelihood_sse(buffer, x, t2);
}

void append_records(CandidateBuffer& buffer, const KernelRecord* records,
                    const std::uint32_t* slots, std::size_t n, const float origin[3], float slab2) {
  buffer.reserve(buffer.count + n);
  if (have_avx2()) {
    append_avx2(buffer, records, slots, n, origin, slab2);
  } else {
    for (std::size_t k = 0; k < n; ++k)
      buffer.push_record(slots[k], records[slots[k]], origin, slab2);
  }
}

float fast_exp(float a) {
  V4 v = V4{} + a;
  return vexp<V4, VI4>(v)[0];
}

const char* simd_path() {
  return have_avx2() ? "avx2+fma" : "sse2";
}

}  // namespace scanclean::detail

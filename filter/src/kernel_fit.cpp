#include "kernel_fit.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

// The 8-wide helpers below return vectors by value; they are always inlined into functions
// compiled for AVX2 or into their SSE2 twins, so the ABI note GCC gives for them does not apply.
#pragma GCC diagnostic ignored "-Wpsabi"

// The loops that sum are written with the compiler's vector types (GCC and Clang), whose lane
// counts are the fit's own: the sums in 4 double lanes (docs/ALGORITHM.md section 6), the
// moments in 8 floats. On x86 they are compiled twice, for AVX2 and for the baseline (SSE2), and
// chosen at run time; elsewhere once, for the baseline (NEON on ARM). Highway's vectors take the
// lane count of the target, which would change the sums' order from one processor to another;
// the loops over single samples, which sum nothing across lanes (making the samples, trimming
// them), are written with Highway (fit_sample_loops.cpp).
#if defined(__x86_64__)
#define SCANCLEAN_AVX2 [[gnu::target("avx2")]]
#else
#define SCANCLEAN_AVX2
#endif

namespace scanclean::detail {
namespace {

typedef float V8f __attribute__((vector_size(32)));
typedef double V4d __attribute__((vector_size(32)));
typedef float V4f __attribute__((vector_size(16)));
// Unaligned stores and loads, through types the compiler knows may sit anywhere.
typedef float V8fu __attribute__((vector_size(32), aligned(4)));
typedef float V4fu __attribute__((vector_size(16), aligned(4)));

[[gnu::always_inline]] inline V4f load4(const float* p) {
  return *reinterpret_cast<const V4fu*>(p);
}
[[gnu::always_inline]] inline V8f load8(const float* p) {
  return *reinterpret_cast<const V8fu*>(p);
}

// Four samples at a time from the padded arrays, widened to double: lane l holds the partial
// sums of the samples k = l mod 4, in sample order (the padding adds exact zeros); the lanes
// are combined as (0 + 1) + (2 + 3).
[[gnu::always_inline]] inline FitSums sums_impl(const FitSampleSet& q) {
  V4d s0{}, sx{}, sy{}, sz{}, sxx{}, syy{}, szz{}, sxy{}, sxz{}, syz{};
  const float *px = q.x.data(), *py = q.y.data(), *pz = q.z.data(), *pt = q.t.data();
  for (std::size_t k = 0; k < q.n; k += 4) {
    const V4d x = __builtin_convertvector(load4(px + k), V4d);
    const V4d y = __builtin_convertvector(load4(py + k), V4d);
    const V4d z = __builtin_convertvector(load4(pz + k), V4d);
    const V4d t = __builtin_convertvector(load4(pt + k), V4d);
    const V4d tx = t * x, ty = t * y, tz = t * z;
    s0 += t;
    sx += tx;
    sy += ty;
    sz += tz;
    sxx += tx * x;
    syy += ty * y;
    szz += tz * z;
    sxy += tx * y;
    sxz += tx * z;
    syz += ty * z;
  }
  auto total = [](const V4d& v) { return (v[0] + v[1]) + (v[2] + v[3]); };
  FitSums s;
  s.s0 = total(s0);
  s.sx = total(sx);
  s.sy = total(sy);
  s.sz = total(sz);
  s.sxx = total(sxx);
  s.syy = total(syy);
  s.szz = total(szz);
  s.sxy = total(sxy);
  s.sxz = total(sxz);
  s.syz = total(syz);
  return s;
}

// AVX2 without FMA: products and sums stay separately rounded, as in the scalar loops.
SCANCLEAN_AVX2 FitSums sums_avx2(const FitSampleSet& q) {
  return sums_impl(q);
}
FitSums sums_sse2(const FitSampleSet& q) {
  return sums_impl(q);
}
// sample_moments' sums: nine moments (x, y, z, xx, yy, zz, xy, xz, yz) in 8 float lanes each,
// sample k in lane k mod 8 (the padding adds exact zeros); the same operations on every target.
constexpr std::size_t kMoments = 9;
[[gnu::always_inline]] inline void moments_impl(const FitSampleSet& q, V8f (&a)[kMoments]) {
  for (V8f& v : a) v = V8f{};
  const float *px = q.x.data(), *py = q.y.data(), *pz = q.z.data();
  for (std::size_t k = 0; k < q.n; k += 8) {
    const V8f x = load8(px + k), y = load8(py + k), z = load8(pz + k);
    a[0] += x;
    a[1] += y;
    a[2] += z;
    a[3] += x * x;
    a[4] += y * y;
    a[5] += z * z;
    a[6] += x * y;
    a[7] += x * z;
    a[8] += y * z;
  }
}
SCANCLEAN_AVX2 void moments_avx2(const FitSampleSet& q, V8f (&a)[kMoments]) {
  moments_impl(q, a);
}
void moments_sse2(const FitSampleSet& q, V8f (&a)[kMoments]) {
  moments_impl(q, a);
}

bool have_avx2() {
#if defined(__x86_64__)
  static const bool yes = __builtin_cpu_supports("avx2");
#else
  static const bool yes = false;  // the baseline loops
#endif
  return yes;
}

}  // namespace

void FitSampleSet::reserve(std::size_t cap) {
  if (capacity() >= cap) return;
  for (auto* v : {&x, &y, &z, &t}) v->resize(cap + kFitLanes);
}

void FitSampleSet::pad() {
  reserve(n);
  const std::size_t end = (n + kFitLanes - 1) / kFitLanes * kFitLanes;
  for (std::size_t k = n; k < end; ++k) x[k] = y[k] = z[k] = t[k] = 0.0f;
}

void FitSampleSet::assign(const FitSample* samples, std::size_t count) {
  reserve(count);
  for (std::size_t k = 0; k < count; ++k) {
    x[k] = static_cast<float>(samples[k].x);
    y[k] = static_cast<float>(samples[k].y);
    z[k] = static_cast<float>(samples[k].z);
    t[k] = static_cast<float>(samples[k].t);
  }
  n = count;
  pad();
}

void FitSampleSet::append_to(std::vector<FitSample>& out) const {
  for (std::size_t k = 0; k < n; ++k) out.push_back({x[k], y[k], z[k], t[k]});
}

SampleMoments sample_moments(const FitSampleSet& samples) {
  V8f a[kMoments];
  if (have_avx2())
    moments_avx2(samples, a);
  else
    moments_sse2(samples, a);
  double s[kMoments];
  for (std::size_t m = 0; m < kMoments; ++m) {
    s[m] = 0;
    for (int l = 0; l < 8; ++l) s[m] += a[m][l];
  }
  SampleMoments out;
  out.n = samples.n;
  if (samples.n == 0) return out;
  const double inv = 1.0 / static_cast<double>(samples.n);
  out.mean = Eigen::Vector3d(s[0], s[1], s[2]) * inv;
  const Eigen::Vector3d& m = out.mean;
  out.cov(0, 0) = s[3] * inv - m.x() * m.x();
  out.cov(1, 1) = s[4] * inv - m.y() * m.y();
  out.cov(2, 2) = s[5] * inv - m.z() * m.z();
  out.cov(0, 1) = out.cov(1, 0) = s[6] * inv - m.x() * m.y();
  out.cov(0, 2) = out.cov(2, 0) = s[7] * inv - m.x() * m.z();
  out.cov(1, 2) = out.cov(2, 1) = s[8] * inv - m.y() * m.z();
  return out;
}

FitSums fit_sums(const FitSampleSet& samples) {
  return have_avx2() ? sums_avx2(samples) : sums_sse2(samples);
}

FitSums fit_sums_scalar(const FitSampleSet& samples) {
  FitSums set[4];
  for (std::size_t k = 0; k < samples.n; ++k) {
    FitSums& s = set[k % 4];
    const double x = samples.x[k], y = samples.y[k], z = samples.z[k], t = samples.t[k];
    s.s0 += t;
    s.sx += t * x;
    s.sy += t * y;
    s.sz += t * z;
    s.sxx += t * x * x;
    s.syy += t * y * y;
    s.szz += t * z * z;
    s.sxy += t * x * y;
    s.sxz += t * x * z;
    s.syz += t * y * z;
  }
  FitSums s;
  for (double FitSums::*f :
       {&FitSums::s0, &FitSums::sx, &FitSums::sy, &FitSums::sz, &FitSums::sxx, &FitSums::syy,
        &FitSums::szz, &FitSums::sxy, &FitSums::sxz, &FitSums::syz})
    s.*f = (set[0].*f + set[1].*f) + (set[2].*f + set[3].*f);
  return s;
}

std::size_t trim_samples_scalar(FitSampleSet& q, const TrimPlane& plane, FitSums& sums) {
  const TrimPlaneF p(plane);
  std::size_t kept = 0;
  for (std::size_t k = 0; k < q.n; ++k) {
    if (p.trims(q.x[k], q.y[k], q.z[k])) {
      downdate_sums(sums, q.x[k], q.y[k], q.z[k], q.t[k]);
      continue;
    }
    q.x[kept] = q.x[k];
    q.y[kept] = q.y[k];
    q.z[kept] = q.z[k];
    q.t[kept] = q.t[k];
    ++kept;
  }
  q.n = kept;
  q.pad();
  return kept;
}

std::size_t make_samples_scalar(const Eigen::Vector3d* p, const std::uint32_t* js, std::size_t m,
                                const Eigen::Vector3d& centre, double h2, double inv_h2,
                                FitSampleSet& out) {
  const std::size_t before = out.n;
  for (std::size_t k = 0; k < m; ++k) {
    const Eigen::Vector3d dj = p[js[k]] - centre;
    const double r2 = dj.squaredNorm();
    if (!(r2 < h2)) continue;
    double t = 1.0 - r2 * inv_h2;
    t *= t;
    t *= t;
    out.x[out.n] = static_cast<float>(dj.x());
    out.y[out.n] = static_cast<float>(dj.y());
    out.z[out.n] = static_cast<float>(dj.z());
    out.t[out.n] = static_cast<float>(t);
    ++out.n;
  }
  return out.n - before;
}

bool smallest_eigenpair(const Eigen::Matrix3d& c, double& lambda, Eigen::Vector3d& v) {
  // The characteristic polynomial f(l) = l^3 - a l^2 + b l - d has three real roots. Left of
  // the smallest, f is negative, increasing and concave (f'' = 6 l - 2 a vanishes at the roots'
  // mean), so Newton's method started there climbs to it from below without passing it.
  const double c00 = c(0, 0), c11 = c(1, 1), c22 = c(2, 2);
  const double c01 = c(0, 1), c02 = c(0, 2), c12 = c(1, 2);
  const double a = c00 + c11 + c22;
  const double b = (c00 * c11 - c01 * c01) + (c00 * c22 - c02 * c02) + (c11 * c22 - c12 * c12);
  const double d =
      c00 * (c11 * c22 - c12 * c12) - c01 * (c01 * c22 - c12 * c02) + c02 * (c01 * c12 - c11 * c02);
  const double r01 = std::abs(c01), r02 = std::abs(c02), r12 = std::abs(c12);
  const double scale = std::max({std::abs(c00), std::abs(c11), std::abs(c22), r01, r02, r12});
  if (!(scale > 0) || !std::isfinite(a + b + d)) return false;
  auto f_at = [&](double x) { return ((x - a) * x + b) * x - d; };
  // The two roots above l: l2 + l3 = a - l, l2 l3 = b - l (a - l); the smaller of them.
  auto second_root = [&](double x) {
    const double p = a - x, q = b - x * p;
    return 0.5 * (p - std::sqrt(std::max(0.0, p * p - 4 * q)));
  };
  // A covariance has no negative eigenvalue beyond rounding: start just below zero, where the
  // first step lands near the smallest root when it is well below the others. If f is not
  // negative there, start from Gershgorin's bound, below every eigenvalue.
  double l = -1e-9 * scale;
  if (!(f_at(l) < 0))
    l = std::min({c00 - r01 - r02, c11 - r01 - r12, c22 - r02 - r12}) - 1e-3 * scale;
  double first_step = 0;
  for (int it = 0; it < 100; ++it) {
    const double f = f_at(l);
    const double df = (3 * l - 2 * a) * l + b;
    if (!(f < 0) || !(df > 0)) break;  // at the root, to rounding
    const double next = l - f / df;
    if (!(next > l)) break;
    const double step = next - l;
    l = next;
    // Newton's method is slow where the two smallest roots are close: there the second step is
    // more than half the first (two thirds where they meet; 0.31 at a ratio of 1 : 6, 0.58 at
    // 1 : 2). Leave those to the full solver.
    if (it == 1 && step > 0.55 * first_step) return false;
    if (it == 0) first_step = step;
    // Converging quadratically, a step this small leaves the next one at rounding.
    if (step < 1e-8 * scale && it > 0) {
      const double f2 = f_at(l), df2 = (3 * l - 2 * a) * l + b;
      if (f2 < 0 && df2 > 0 && l - f2 / df2 > l) l -= f2 / df2;
      break;
    }
  }
  // Closer to l than 1e-3 of the largest entry, the eigenvector is ill-determined: leave those
  // to the full solver.
  const double l2 = second_root(l);
  if (!(l2 - l > 1e-3 * scale)) return false;
  // The eigenvector: the largest cross product of two rows of c - l I.
  const Eigen::Vector3d r0(c00 - l, c01, c02), r1(c01, c11 - l, c12), r2(c02, c12, c22 - l);
  const Eigen::Vector3d x0 = r0.cross(r1), x1 = r0.cross(r2), x2 = r1.cross(r2);
  const double n0 = x0.squaredNorm(), n1 = x1.squaredNorm(), n2 = x2.squaredNorm();
  const Eigen::Vector3d& best = n0 >= n1 && n0 >= n2 ? x0 : (n1 >= n2 ? x1 : x2);
  const double nb = std::max({n0, n1, n2});
  if (!(nb > 0)) return false;
  lambda = l;
  v = best / std::sqrt(nb);
  return true;
}

bool fit_samples(std::vector<FitSample>& samples, const Eigen::Vector3d& centre, double h,
                 int k_min, double eigen_floor, KernelFit& out) {
  thread_local FitSampleSet set;
  set.assign(samples.data(), samples.size());
  const bool ok = fit_samples(set, centre, h, k_min, eigen_floor, out);
  samples.clear();
  set.append_to(samples);
  return ok;
}

bool fit_samples(FitSampleSet& nb, const Eigen::Vector3d& centre, double h, int k_min,
                 double eigen_floor, KernelFit& out) {
  constexpr double kTrim = 3.0;
  constexpr int kRefits = 2;
  const double h2 = h * h, inv_h2 = 1.0 / h2;
  const double floor2 = eigen_floor * eigen_floor;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
  Eigen::Vector3d m;
  Eigen::Matrix3d cov;
  double s0_final = 0;
  bool full = false;         // the full solve in every round
  bool full_of_cov = false;  // es holds the full solve of cov
  nb.pad();
  // The sums of the first round are formed over the samples; each later round's are the last
  // round's with the trimmed samples' terms taken out (a few of some 250: a pass over them all
  // again cost more than the eigen-decomposition).
  FitSums fs = fit_sums(nb);
  for (int round = 0;; ++round) {
    const double s0 = fs.s0, sx = fs.sx, sy = fs.sy, sz = fs.sz, sxx = fs.sxx, syy = fs.syy,
                 szz = fs.szz, sxy = fs.sxy, sxz = fs.sxz, syz = fs.syz;
    if (static_cast<int>(nb.n) < k_min || !(s0 > 0)) return false;
    s0_final = s0;
    m = Eigen::Vector3d(sx / s0, sy / s0, sz / s0);
    Eigen::Matrix3d c;
    c(0, 0) = sxx / s0 - m.x() * m.x();
    c(1, 1) = syy / s0 - m.y() * m.y();
    c(2, 2) = szz / s0 - m.z() * m.z();
    c(0, 1) = c(1, 0) = sxy / s0 - m.x() * m.y();
    c(0, 2) = c(2, 0) = sxz / s0 - m.x() * m.z();
    c(1, 2) = c(2, 1) = syz / s0 - m.y() * m.z();
    // Solve in units of h^2 (well scaled); closed form, checked against the QR solver in tests.
    cov = c * inv_h2;
    full_of_cov = false;
    if (round == kRefits) break;
    // Trim (in units of h): residuals from the plane beyond kTrim standard deviations. The plane
    // needs only the smallest eigenpair; the full solve is left to the last round.
    // Where that is slow (the two smallest eigenvalues close: noise as thick as the kernel is
    // wide), the full solve is used for every round, and the last round's is kept.
    Eigen::Vector3d nrm;
    double lambda0;
    if (full || !smallest_eigenpair(cov, lambda0, nrm)) {
      full = full_of_cov = true;
      es.computeDirect(cov);
      nrm = es.eigenvectors().col(0);
      lambda0 = es.eigenvalues()[0];
    }
    const double var = std::max(lambda0, floor2);
    const double limit2 = kTrim * kTrim * var * h2;
    const std::size_t before = nb.n;
    const TrimPlane plane{{nrm.x(), nrm.y(), nrm.z()}, {m.x(), m.y(), m.z()}, limit2};
    if (trim_samples(nb, plane, fs) == before) break;
  }
  if (!full_of_cov) es.computeDirect(cov);
  out.weight = s0_final;
  out.m = m;
  out.cov = cov * h2;
  out.c = centre + m;
  out.lambda = es.eigenvalues().cwiseMax(0.0) * h2;
  out.e = es.eigenvectors();
  return true;
}

}  // namespace scanclean::detail

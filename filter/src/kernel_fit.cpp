#include "kernel_fit.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstring>

namespace scanclean::detail {
namespace {

typedef double V4d __attribute__((vector_size(32)));
typedef long long V4l __attribute__((vector_size(32)));

// Four samples at a time, transposed to (x0 x1 x2 x3), (y...), (z...), (t...): lane l holds
// the partial sums of the samples k = l mod 4 (fit_sums_scalar's sets), added in sample order;
// the few samples past the last multiple of four go to lanes 0, 1, 2 alone. The lanes are
// combined as (0 + 1) + (2 + 3).
[[gnu::always_inline]] inline FitSums sums_impl(const FitSample* q, std::size_t n) {
  static_assert(sizeof(FitSample) == sizeof(V4d), "a sample is four doubles");
  V4d s0{}, sx{}, sy{}, sz{}, sxx{}, syy{}, szz{}, sxy{}, sxz{}, syz{};
  auto add = [&](V4d x, V4d y, V4d z, V4d t) {
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
  };
  std::size_t k = 0;
  for (; k + 4 <= n; k += 4) {
    // Four loads into separate vectors (an array would go through the stack), rows: samples
    // (x y z t); then a 4 x 4 transpose to columns: fields.
    V4d r0, r1, r2, r3;
    std::memcpy(&r0, &q[k], sizeof r0);
    std::memcpy(&r1, &q[k + 1], sizeof r1);
    std::memcpy(&r2, &q[k + 2], sizeof r2);
    std::memcpy(&r3, &q[k + 3], sizeof r3);
    const V4d a = __builtin_shuffle(r0, r1, V4l{0, 4, 2, 6});  // x0 x1 z0 z1
    const V4d b = __builtin_shuffle(r0, r1, V4l{1, 5, 3, 7});  // y0 y1 t0 t1
    const V4d c = __builtin_shuffle(r2, r3, V4l{0, 4, 2, 6});  // x2 x3 z2 z3
    const V4d d = __builtin_shuffle(r2, r3, V4l{1, 5, 3, 7});  // y2 y3 t2 t3
    add(__builtin_shuffle(a, c, V4l{0, 1, 4, 5}), __builtin_shuffle(b, d, V4l{0, 1, 4, 5}),
        __builtin_shuffle(a, c, V4l{2, 3, 6, 7}), __builtin_shuffle(b, d, V4l{2, 3, 6, 7}));
  }
  if (k < n) {  // the rest in lanes 0.., zero weight (adds exact zeros) in the others
    V4d x{}, y{}, z{}, t{};
    for (std::size_t l = 0; k + l < n; ++l) {
      x[l] = q[k + l].x;
      y[l] = q[k + l].y;
      z[l] = q[k + l].z;
      t[l] = q[k + l].t;
    }
    add(x, y, z, t);
  }
  auto total = [](V4d v) { return (v[0] + v[1]) + (v[2] + v[3]); };
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

// AVX2 without FMA: the products and sums stay separately rounded, as in the scalar loop.
[[gnu::target("avx2")]] FitSums sums_avx2(const FitSample* q, std::size_t n) {
  return sums_impl(q, n);
}
FitSums sums_sse2(const FitSample* q, std::size_t n) {
  return sums_impl(q, n);
}

// One trimming pass (trim_samples): sample k is kept when !(r r > limit2), with its residual
// r = (n_x (x - m_x) + n_y (y - m_y)) + n_z (z - m_z); the kept ones move down in order, the
// others' terms leave the sums. Four samples at a time: their residuals are formed in a vector,
// with the scalar loop's operations (no fused multiply-add), and a block with none trimmed is
// kept whole; so the results are the scalar loop's, bit for bit.
[[gnu::always_inline]] inline void downdate(FitSums& fs, const FitSample& q) {
  const double tx = q.t * q.x, ty = q.t * q.y, tz = q.t * q.z;
  fs.s0 -= q.t;
  fs.sx -= tx;
  fs.sy -= ty;
  fs.sz -= tz;
  fs.sxx -= tx * q.x;
  fs.syy -= ty * q.y;
  fs.szz -= tz * q.z;
  fs.sxy -= tx * q.y;
  fs.sxz -= tx * q.z;
  fs.syz -= ty * q.z;
}

[[gnu::always_inline]] inline double residual(const FitSample& q, const TrimPlane& p) {
  return p.n[0] * (q.x - p.m[0]) + p.n[1] * (q.y - p.m[1]) + p.n[2] * (q.z - p.m[2]);
}

[[gnu::always_inline]] inline std::size_t trim_impl(FitSample* q, std::size_t n, const TrimPlane& p,
                                                    FitSums& fs) {
  const V4d nx = {p.n[0], p.n[0], p.n[0], p.n[0]}, ny = {p.n[1], p.n[1], p.n[1], p.n[1]},
            nz = {p.n[2], p.n[2], p.n[2], p.n[2]};
  const V4d mx = {p.m[0], p.m[0], p.m[0], p.m[0]}, my = {p.m[1], p.m[1], p.m[1], p.m[1]},
            mz = {p.m[2], p.m[2], p.m[2], p.m[2]};
  const V4d lim = {p.limit2, p.limit2, p.limit2, p.limit2};
  // The mask of the samples of block k to trim (bit l: sample k + l); r0..r3 its rows.
  auto block = [&](std::size_t k, V4d& r0, V4d& r1, V4d& r2, V4d& r3) {
    std::memcpy(&r0, &q[k], sizeof r0);
    std::memcpy(&r1, &q[k + 1], sizeof r1);
    std::memcpy(&r2, &q[k + 2], sizeof r2);
    std::memcpy(&r3, &q[k + 3], sizeof r3);
    const V4d a = __builtin_shuffle(r0, r1, V4l{0, 4, 2, 6});  // x0 x1 z0 z1
    const V4d b = __builtin_shuffle(r0, r1, V4l{1, 5, 3, 7});  // y0 y1 t0 t1
    const V4d c = __builtin_shuffle(r2, r3, V4l{0, 4, 2, 6});  // x2 x3 z2 z3
    const V4d d = __builtin_shuffle(r2, r3, V4l{1, 5, 3, 7});  // y2 y3 t2 t3
    const V4d x = __builtin_shuffle(a, c, V4l{0, 1, 4, 5});
    const V4d y = __builtin_shuffle(b, d, V4l{0, 1, 4, 5});
    const V4d z = __builtin_shuffle(a, c, V4l{2, 3, 6, 7});
    const V4d r = nx * (x - mx) + ny * (y - my) + nz * (z - mz);
    const V4l out = r * r > lim;
    return static_cast<unsigned>((out[0] & 1) | (out[1] & 2) | (out[2] & 4) | (out[3] & 8));
  };
  std::size_t k = 0;
  V4d r[4];
  unsigned mask = 0;
  // Up to the first block with a sample to trim, nothing moves.
  for (; k + 4 <= n; k += 4)
    if ((mask = block(k, r[0], r[1], r[2], r[3])) != 0) break;
  std::size_t kept = k;
  bool loaded = k + 4 <= n;  // block k is in r and mask already
  for (; k + 4 <= n; k += 4) {
    if (!loaded) mask = block(k, r[0], r[1], r[2], r[3]);
    loaded = false;
    for (int l = 0; l < 4; ++l) {
      if (mask & (1u << l)) {
        downdate(fs, q[k + l]);
      } else {
        std::memcpy(&q[kept++], &r[l], sizeof r[l]);
      }
    }
  }
  for (; k < n; ++k) {
    const FitSample s = q[k];
    const double e = residual(s, p);
    if (!(e * e > p.limit2))
      q[kept++] = s;
    else
      downdate(fs, s);
  }
  return kept;
}

// AVX2 without FMA, as the sums.
[[gnu::target("avx2")]] std::size_t trim_avx2(FitSample* q, std::size_t n, const TrimPlane& p,
                                              FitSums& fs) {
  return trim_impl(q, n, p, fs);
}
std::size_t trim_sse2(FitSample* q, std::size_t n, const TrimPlane& p, FitSums& fs) {
  return trim_impl(q, n, p, fs);
}

[[gnu::always_inline]] inline std::size_t make_impl(const Eigen::Vector3d* p,
                                                    const std::uint32_t* js, std::size_t m,
                                                    const Eigen::Vector3d& c, double h2,
                                                    double inv_h2, FitSample* out) {
  const V4d cx = {c.x(), c.x(), c.x(), c.x()}, cy = {c.y(), c.y(), c.y(), c.y()},
            cz = {c.z(), c.z(), c.z(), c.z()};
  const V4d vh2 = {h2, h2, h2, h2}, vinv = {inv_h2, inv_h2, inv_h2, inv_h2};
  const V4d one = {1, 1, 1, 1};
  std::size_t n = 0, k = 0;
  for (; k + 4 <= m; k += 4) {
    const Eigen::Vector3d& a = p[js[k]];
    const Eigen::Vector3d& b = p[js[k + 1]];
    const Eigen::Vector3d& e = p[js[k + 2]];
    const Eigen::Vector3d& f = p[js[k + 3]];
    const V4d dx = V4d{a.x(), b.x(), e.x(), f.x()} - cx;
    const V4d dy = V4d{a.y(), b.y(), e.y(), f.y()} - cy;
    const V4d dz = V4d{a.z(), b.z(), e.z(), f.z()} - cz;
    const V4d r2 = (dx * dx + dy * dy) + dz * dz;
    const V4l in = r2 < vh2;
    V4d t = one - r2 * vinv;
    t *= t;
    t *= t;
    // Rows (dx dy dz t) of the four samples; each is written at out[n] and counted if kept.
    const V4d lo0 = __builtin_shuffle(dx, dy, V4l{0, 4, 2, 6});  // dx0 dy0 dx2 dy2
    const V4d lo1 = __builtin_shuffle(dx, dy, V4l{1, 5, 3, 7});  // dx1 dy1 dx3 dy3
    const V4d hi0 = __builtin_shuffle(dz, t, V4l{0, 4, 2, 6});   // dz0 t0 dz2 t2
    const V4d hi1 = __builtin_shuffle(dz, t, V4l{1, 5, 3, 7});   // dz1 t1 dz3 t3
    const V4d rows[4] = {
        __builtin_shuffle(lo0, hi0, V4l{0, 1, 4, 5}), __builtin_shuffle(lo1, hi1, V4l{0, 1, 4, 5}),
        __builtin_shuffle(lo0, hi0, V4l{2, 3, 6, 7}), __builtin_shuffle(lo1, hi1, V4l{2, 3, 6, 7})};
    for (int l = 0; l < 4; ++l) {
      std::memcpy(&out[n], &rows[l], sizeof rows[l]);
      n += in[l] != 0 ? 1 : 0;
    }
  }
  for (; k < m; ++k) {
    const Eigen::Vector3d dj = p[js[k]] - c;
    const double r2 = (dj.x() * dj.x() + dj.y() * dj.y()) + dj.z() * dj.z();
    if (!(r2 < h2)) continue;
    double t = 1.0 - r2 * inv_h2;
    t *= t;
    t *= t;
    out[n++] = {dj.x(), dj.y(), dj.z(), t};
  }
  return n;
}

[[gnu::target("avx2")]] std::size_t make_avx2(const Eigen::Vector3d* p, const std::uint32_t* js,
                                              std::size_t m, const Eigen::Vector3d& c, double h2,
                                              double inv_h2, FitSample* out) {
  return make_impl(p, js, m, c, h2, inv_h2, out);
}
std::size_t make_sse2(const Eigen::Vector3d* p, const std::uint32_t* js, std::size_t m,
                      const Eigen::Vector3d& c, double h2, double inv_h2, FitSample* out) {
  return make_impl(p, js, m, c, h2, inv_h2, out);
}

bool have_avx2() {
  static const bool yes = __builtin_cpu_supports("avx2");
  return yes;
}

}  // namespace

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

FitSums fit_sums(const FitSample* samples, std::size_t n) {
  return have_avx2() ? sums_avx2(samples, n) : sums_sse2(samples, n);
}

std::size_t make_samples(const Eigen::Vector3d* p, const std::uint32_t* js, std::size_t m,
                         const Eigen::Vector3d& centre, double h2, double inv_h2, FitSample* out) {
  return have_avx2() ? make_avx2(p, js, m, centre, h2, inv_h2, out)
                     : make_sse2(p, js, m, centre, h2, inv_h2, out);
}

std::size_t make_samples_scalar(const Eigen::Vector3d* p, const std::uint32_t* js, std::size_t m,
                                const Eigen::Vector3d& centre, double h2, double inv_h2,
                                FitSample* out) {
  std::size_t n = 0;
  for (std::size_t k = 0; k < m; ++k) {
    const Eigen::Vector3d dj = p[js[k]] - centre;
    const double r2 = dj.squaredNorm();
    if (!(r2 < h2)) continue;
    double t = 1.0 - r2 * inv_h2;
    t *= t;
    t *= t;
    out[n++] = {dj.x(), dj.y(), dj.z(), t};
  }
  return n;
}

std::size_t trim_samples(FitSample* samples, std::size_t n, const TrimPlane& plane, FitSums& sums) {
  return have_avx2() ? trim_avx2(samples, n, plane, sums) : trim_sse2(samples, n, plane, sums);
}

std::size_t trim_samples_scalar(FitSample* samples, std::size_t n, const TrimPlane& plane,
                                FitSums& sums) {
  std::size_t kept = 0;
  for (std::size_t k = 0; k < n; ++k) {
    const FitSample q = samples[k];
    const double r = residual(q, plane);
    if (!(r * r > plane.limit2))
      samples[kept++] = q;
    else
      downdate(sums, q);
  }
  return kept;
}

FitSums fit_sums_scalar(const FitSample* samples, std::size_t n) {
  FitSums set[4];
  for (std::size_t k = 0; k < n; ++k) {
    FitSums& s = set[k % 4];
    const FitSample& q = samples[k];
    const double t = q.t;
    s.s0 += t;
    s.sx += t * q.x;
    s.sy += t * q.y;
    s.sz += t * q.z;
    s.sxx += t * q.x * q.x;
    s.syy += t * q.y * q.y;
    s.szz += t * q.z * q.z;
    s.sxy += t * q.x * q.y;
    s.sxz += t * q.x * q.z;
    s.syz += t * q.y * q.z;
  }
  FitSums s;
  for (double FitSums::*f :
       {&FitSums::s0, &FitSums::sx, &FitSums::sy, &FitSums::sz, &FitSums::sxx, &FitSums::syy,
        &FitSums::szz, &FitSums::sxy, &FitSums::sxz, &FitSums::syz})
    s.*f = (set[0].*f + set[1].*f) + (set[2].*f + set[3].*f);
  return s;
}

bool fit_samples(std::vector<FitSample>& samples, const Eigen::Vector3d& centre, double h,
                 int k_min, double eigen_floor, KernelFit& out) {
  std::size_t n = samples.size();
  const bool ok = fit_samples(samples.data(), n, centre, h, k_min, eigen_floor, out);
  samples.resize(n);
  return ok;
}

bool fit_samples(FitSample* nb, std::size_t& n, const Eigen::Vector3d& centre, double h, int k_min,
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
  // The sums of the first round are formed over the samples; each later round's are the last
  // round's with the trimmed samples' terms taken out (a few of some 250: a pass over them all
  // again cost more than the eigen-decomposition).
  FitSums fs = fit_sums(nb, n);
  for (int round = 0;; ++round) {
    const double s0 = fs.s0, sx = fs.sx, sy = fs.sy, sz = fs.sz, sxx = fs.sxx, syy = fs.syy,
                 szz = fs.szz, sxy = fs.sxy, sxz = fs.sxz, syz = fs.syz;
    if (static_cast<int>(n) < k_min || !(s0 > 0)) return false;
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
    const std::size_t before = n;
    const TrimPlane plane{{nrm.x(), nrm.y(), nrm.z()}, {m.x(), m.y(), m.z()}, limit2};
    const std::size_t kept = trim_samples(nb, n, plane, fs);
    n = kept;
    if (n == before) break;
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

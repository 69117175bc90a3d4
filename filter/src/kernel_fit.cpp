#include "kernel_fit.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cstring>

namespace scanclean::detail {
namespace {

typedef double V4d __attribute__((vector_size(32)));
typedef long long V4l __attribute__((vector_size(32)));

// Three accumulators of four lanes: (t x, t y, t z, t), (t x x, t y y, t z z, -), and
// (t x y, t x z, t y z, -); every lane is one of the scalar sums, added in sample order.
[[gnu::always_inline]] inline FitSums sums_impl(const FitSample* q, std::size_t n) {
  static_assert(sizeof(FitSample) == sizeof(V4d), "a sample is four doubles");
  V4d a{}, b{}, c{};
  for (std::size_t k = 0; k < n; ++k) {
    V4d v;  // x y z t
    std::memcpy(&v, &q[k], sizeof v);
    V4d xyz1 = v;
    xyz1[3] = 1.0;
    const V4d t = V4d{} + v[3];
    const V4d tx = t * xyz1;  // t x, t y, t z, t
    a += tx;
    b += tx * xyz1;
    c += __builtin_shuffle(tx, V4l{0, 0, 1, 1}) * __builtin_shuffle(v, V4l{1, 2, 2, 2});
  }
  FitSums s;
  s.sx = a[0];
  s.sy = a[1];
  s.sz = a[2];
  s.s0 = a[3];
  s.sxx = b[0];
  s.syy = b[1];
  s.szz = b[2];
  s.sxy = c[0];
  s.sxz = c[1];
  s.syz = c[2];
  return s;
}

// AVX2 without FMA: the products and sums stay separately rounded, as in the scalar loop.
[[gnu::target("avx2")]] FitSums sums_avx2(const FitSample* q, std::size_t n) {
  return sums_impl(q, n);
}
FitSums sums_sse2(const FitSample* q, std::size_t n) {
  return sums_impl(q, n);
}

bool have_avx2() {
  static const bool yes = __builtin_cpu_supports("avx2");
  return yes;
}

}  // namespace

FitSums fit_sums(const FitSample* samples, std::size_t n) {
  return have_avx2() ? sums_avx2(samples, n) : sums_sse2(samples, n);
}

FitSums fit_sums_scalar(const FitSample* samples, std::size_t n) {
  FitSums s;
  for (std::size_t k = 0; k < n; ++k) {
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
  return s;
}

bool fit_samples(std::vector<FitSample>& nb, const Eigen::Vector3d& centre, double h, int k_min,
                 double eigen_floor, KernelFit& out) {
  constexpr double kTrim = 3.0;
  constexpr int kRefits = 2;
  const double h2 = h * h, inv_h2 = 1.0 / h2;
  const double floor2 = eigen_floor * eigen_floor;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
  Eigen::Vector3d m;
  Eigen::Matrix3d cov;
  double s0_final = 0;
  for (int round = 0;; ++round) {
    const FitSums fs = fit_sums(nb.data(), nb.size());
    const double s0 = fs.s0, sx = fs.sx, sy = fs.sy, sz = fs.sz, sxx = fs.sxx, syy = fs.syy,
                 szz = fs.szz, sxy = fs.sxy, sxz = fs.sxz, syz = fs.syz;
    if (static_cast<int>(nb.size()) < k_min || !(s0 > 0)) return false;
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
    es.computeDirect(cov);
    if (round == kRefits) break;
    // Trim (in units of h): residuals from the plane beyond kTrim standard deviations.
    const Eigen::Vector3d n = es.eigenvectors().col(0);
    const double var = std::max(es.eigenvalues()[0], floor2);
    const double limit2 = kTrim * kTrim * var * h2;
    const std::size_t before = nb.size();
    nb.erase(std::remove_if(nb.begin(), nb.end(),
                            [&](const FitSample& q) {
                              const double r = n.x() * (q.x - m.x()) + n.y() * (q.y - m.y()) +
                                               n.z() * (q.z - m.z());
                              return r * r > limit2;
                            }),
             nb.end());
    if (nb.size() == before) break;
  }
  out.weight = s0_final;
  out.m = m;
  out.cov = cov * h2;
  out.c = centre + m;
  out.lambda = es.eigenvalues().cwiseMax(0.0) * h2;
  out.e = es.eigenvectors();
  return true;
}

}  // namespace scanclean::detail

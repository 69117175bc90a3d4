#include "plane_refit.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdint>

#include "point_moments.h"

namespace scanclean::detail {

bool refit_own_plane(const std::vector<FitSample>& samples, const Eigen::Vector3d& centre, double h,
                     const PlaneRefit& prm, KernelFit& fit) {
  if (!wants_refit(fit, prm)) return false;
  const double spread = std::sqrt(fit.lambda[0]);
  constexpr int kRounds = 3;
  constexpr double kMinOther = 0.1;
  const double band = 3.0 * prm.sigma;
  thread_local std::vector<FitSample> sel;
  Eigen::Vector3d n = fit.e.col(0);
  Eigen::Vector3d anchor = Eigen::Vector3d::Zero();  // the centre point
  KernelFit trial;
  double total = 0;
  for (const FitSample& q : samples) total += q.t;
  for (int round = 0; round < kRounds; ++round) {
    sel.clear();
    double kept = 0;
    for (const FitSample& q : samples) {
      const double r =
          n.x() * (q.x - anchor.x()) + n.y() * (q.y - anchor.y()) + n.z() * (q.z - anchor.z());
      if (std::abs(r) < band) {
        sel.push_back(q);
        kept += q.t;
      }
    }
    // The first band around the centre point's plane leaving out less than half the share
    // asked for below: a noisy plane (most kernels that ask for the refit at 2-3 % noise),
    // not worth the refits.
    if (round == 0 && !(kept < (1.0 - 0.5 * kMinOther) * total)) return false;
    if (!fit_samples(sel, centre, h, prm.k_min, prm.eigen_floor, trial)) return false;
    n = trial.e.col(0);
    anchor = trial.m;
  }
  // A second structure must hold a real share of the neighbourhood: on a noisy plane whose
  // spread is merely high by chance the band keeps almost everything (over 99 %).
  if (!(trial.weight < (1.0 - kMinOther) * total)) return false;
  if (!(std::sqrt(trial.lambda[0]) < spread)) return false;
  const Eigen::Vector3f n_kept = fit.n;  // the caller's (a sensor normal stays)
  fit = trial;
  fit.n = n_kept;
  return true;
}

namespace {

struct SidePlane {
  Eigen::Vector3d m = Eigen::Vector3d::Zero();   //!< centroid (offset from the centre point)
  Eigen::Vector3d n = Eigen::Vector3d::UnitZ();  //!< unit normal
  double weight = 0;                             //!< sum of the chi weights of its samples
  int count = 0;
};

// The chi-weighted weight, mean and covariance of the samples.
struct Moments {
  double w = 0;
  Eigen::Vector3d m = Eigen::Vector3d::Zero();
  Eigen::Matrix3d c = Eigen::Matrix3d::Zero();
};
Moments chi_moments(const std::vector<FitSample>& s) {
  Moments mo;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (const FitSample& q : s) {
    mo.w += q.t;
    sum += q.t * Eigen::Vector3d(q.x, q.y, q.z);
  }
  if (!(mo.w > 0)) return mo;
  mo.m = sum / mo.w;
  for (const FitSample& q : s) {
    const Eigen::Vector3d d = Eigen::Vector3d(q.x, q.y, q.z) - mo.m;
    mo.c.noalias() += q.t * d * d.transpose();
  }
  mo.c /= mo.w;
  return mo;
}

// The unweighted moments of samples (each counted once) and the chi weights they carry: one
// pass feeds a plane per side.
struct PlaneSums {
  PointMoments m;
  double chi = 0;
  void add(const FitSample& q) {
    m.add(q.x, q.y, q.z);
    chi += q.t;
  }
};

// The plane of the summed samples (every sample counted once, not by its chi weight, which would
// let the blurred apex near the centre flatten the wedge), with the mean squared residual it
// leaves (its smallest eigenvalue); false with fewer than k_min samples. The offsets are within
// h of the centre point, so the covariance from the raw sums loses nothing that matters in
// double.
bool plane_of(const PlaneSums& sums, int k_min, SidePlane& out, double* r2 = nullptr) {
  if (sums.m.n < std::max(3, k_min)) return false;
  const Eigen::Vector3d m = sums.m.mean();
  const Eigen::Matrix3d c = sums.m.second() - m * m.transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
  es.computeDirect(c);
  out.m = m;
  out.n = es.eigenvectors().col(0);
  out.weight = sums.chi;
  out.count = static_cast<int>(sums.m.n);
  if (r2) *r2 = std::max(0.0, es.eigenvalues()(0));
  return true;
}

// plane_of on every sample.
bool fit_plane(const std::vector<FitSample>& s, int k_min, SidePlane& out, double* r2 = nullptr) {
  PlaneSums sums;
  for (const FitSample& q : s) sums.add(q);
  return plane_of(sums, k_min, out, r2);
}

struct Wedge {
  SidePlane plane[2];
  Eigen::Vector3d b = Eigen::Vector3d::UnitX();  //!< normal of the plane separating the sides
  Eigen::Vector3d p = Eigen::Vector3d::Zero();   //!< a point of the planes' line
  double r2 = -1;  //!< mean squared residual of the samples from their side's plane
  //! The side of a point (offset from the centre point): 1 where b.(q - p) > 0.
  std::uint8_t side_of(const Eigen::Vector3d& q) const { return b.dot(q - p) > 0 ? 1 : 0; }
};

// One wedge fit: the samples split by the plane through their centroid m0 normal to u, then
// kCreaseRounds rounds of (a plane per side; the samples given to the sides by the plane through
// the two planes' line that separates the sides' centroids), stopping early once no sample
// changes sides (the next round would repeat this one). `side` receives the last split.
// Returns false where the wedge degenerates (a side too small, the planes parallel).
bool fit_wedge(const std::vector<FitSample>& s, const Eigen::Vector3d& m0, const Eigen::Vector3d& u,
               int k_min, std::vector<std::uint8_t>& side, Wedge& w) {
  const std::size_t ns = s.size();
  PlaneSums sums[2];
  for (std::size_t k = 0; k < ns; ++k) {
    side[k] = (Eigen::Vector3d(s[k].x, s[k].y, s[k].z) - m0).dot(u) > 0 ? 1 : 0;
    sums[side[k]].add(s[k]);
  }
  for (int round = 0; round < kCreaseRounds; ++round) {
    SidePlane(&pl)[2] = w.plane;
    if (!plane_of(sums[0], k_min, pl[0]) || !plane_of(sums[1], k_min, pl[1])) return false;
    const Eigen::Vector3d line = pl[0].n.cross(pl[1].n);
    if (!(line.squaredNorm() > 1e-6)) return false;
    Eigen::Matrix3d a;
    a.row(0) = pl[0].n.transpose();
    a.row(1) = pl[1].n.transpose();
    a.row(2) = line.transpose();
    w.p = a.inverse() * Eigen::Vector3d(pl[0].n.dot(pl[0].m), pl[1].n.dot(pl[1].m),
                                        line.dot(0.5 * (pl[0].m + pl[1].m)));
    // Of the two bisecting planes through the line, the one that separates the centroids.
    const Eigen::Vector3d gap = pl[1].m - pl[0].m;
    w.b = (pl[0].n - pl[1].n).normalized();
    const Eigen::Vector3d b2 = (pl[0].n + pl[1].n).normalized();
    if (std::abs(b2.dot(gap)) > std::abs(w.b.dot(gap))) w.b = b2;
    if (w.b.dot(pl[1].m - w.p) < 0) w.b = -w.b;
    // The new split, its residual from the planes, and the next round's sums, in one pass.
    double sum = 0;
    std::size_t moved = 0;
    sums[0] = sums[1] = PlaneSums();
    for (std::size_t k = 0; k < ns; ++k) {
      const Eigen::Vector3d q(s[k].x, s[k].y, s[k].z);
      const std::uint8_t now = w.side_of(q);
      moved += now != side[k] ? 1 : 0;
      side[k] = now;
      const double r = pl[now].n.dot(q - pl[now].m);
      sum += r * r;
      sums[now].add(s[k]);
    }
    w.r2 = sum / static_cast<double>(ns);
    if (moved == 0) break;
  }
  return true;
}

// How much more of the samples' mean squared residual from `plane` a parabola across the line
// (along v, in the plane) explains than a line does: about sigma^2 / count on a flat face, the
// bend's own share on an arc.
double bend_across(const std::vector<FitSample>& s, const SidePlane& plane,
                   const Eigen::Vector3d& v) {
  Eigen::Matrix3d a = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  double rr = 0;
  for (const FitSample& q : s) {
    const Eigen::Vector3d x = Eigen::Vector3d(q.x, q.y, q.z) - plane.m;
    const double t = v.dot(x), r = plane.n.dot(x);
    const Eigen::Vector3d f(1, t, t * t);
    a.noalias() += f * f.transpose();
    b += r * f;
    rr += r * r;
  }
  // The residual sums of squares of the least-squares fits: rr - b^T A^-1 b.
  const Eigen::Matrix2d a2 = a.topLeftCorner<2, 2>();
  const Eigen::Vector2d b2 = b.head<2>();
  const double line = rr - b2.dot(a2.ldlt().solve(b2));
  const double parabola = rr - b.dot(a.ldlt().solve(b));
  return (line - parabola) / static_cast<double>(s.size());
}

}  // namespace

bool split_crease(const std::vector<FitSample>& samples, const Eigen::Vector3d& centre,
                  const PlaneRefit& prm, KernelFit& fit, CreaseSide* side_out) {
  const std::size_t ns = samples.size();
  if (!wants_split(fit, prm) || ns < 2 * static_cast<std::size_t>(prm.k_min)) return false;
  double total = 0;
  for (const FitSample& q : samples) total += q.t;
  thread_local std::vector<std::uint8_t> side;
  side.resize(ns);
  SidePlane one;
  double r2_one = 0;  // the mean squared residual the single plane leaves
  if (!fit_plane(samples, prm.k_min, one, &r2_one)) return false;
  // Where the plane leaves the samples alike not much more than it leaves them weighted by chi,
  // nothing bends away from it towards the rim of the ball: no crease (a cheap test first; at
  // 2-3 % noise most kernels' spread asks for the refit).
  if (!(r2_one > kCreaseBend * fit.lambda[0])) return false;
  double best_r2 = kCreaseGain * r2_one;  // to beat
  Wedge best;
  bool found = false;
  for (int dir = 0; dir < kCreaseDirections; ++dir) {
    const double a = M_PI * dir / kCreaseDirections;
    const Eigen::Vector3d u = std::cos(a) * fit.e.col(1) + std::sin(a) * fit.e.col(2);
    Wedge w;
    if (!fit_wedge(samples, one.m, u, prm.k_min, side, w) || !(w.r2 < best_r2)) continue;
    if (std::abs(w.plane[0].n.dot(w.plane[1].n)) > kCreaseCos) continue;  // nearly parallel
    if (std::min(w.plane[0].weight, w.plane[1].weight) < kCreaseMinShare * total) continue;
    best_r2 = w.r2;
    best = w;
    found = true;
  }
  if (!found) return false;
  // Two planes must explain the samples to the noise: a surface bent within h (a small sphere,
  // a torus' tube) is also fitted better by a wedge than by one plane, but leaves more.
  if (!(best.r2 < kCreaseSpread * kCreaseSpread * prm.sigma * prm.sigma)) return false;
  // The kernel is fitted on the centre point's side, on the samples that lie on that side of
  // the separating plane and farther than kCreaseMargin noise sigma from the line along the
  // side's own plane. (Near the line the two sides' noise mixes: there the oblique separating
  // plane alone would keep a side's samples by the sign of their noise and tilt the fit, and a
  // cut along the plane alone would take in the other side's samples pushed across.)
  const std::uint8_t own = best.side_of(Eigen::Vector3d::Zero());
  const SidePlane& pl = best.plane[own];
  Eigen::Vector3d v = pl.n.cross(best.plane[1 - own].n).cross(pl.n).normalized();
  if (v.dot(pl.m - best.p) < 0) v = -v;  // into the side
  const double margin = kCreaseMargin * prm.sigma;
  thread_local std::vector<FitSample> sel;
  sel.clear();
  for (const FitSample& q : samples) {
    const Eigen::Vector3d x(q.x, q.y, q.z);
    if (best.side_of(x) == own && v.dot(x - best.p) > margin) sel.push_back(q);
  }
  // The kernel's frame is the side's plane (fitted on every sample of the side alike): with the
  // chi weights of the centre point, the side's samples can spread less across the line than
  // the noise does along the normal, and their weighted PCA would take that direction for the
  // normal.
  if (static_cast<int>(sel.size()) < prm.k_min) return false;
  const Moments mo = chi_moments(sel);
  if (!(mo.w > 0)) return false;
  const Eigen::Vector3d& m = mo.m;
  const Eigen::Matrix3d& c = mo.c;
  // The side's plane again, on the selection (without the samples near the line).
  SidePlane own_plane;
  if (!fit_plane(sel, prm.k_min, own_plane)) return false;
  const Eigen::Vector3d n = own_plane.n;
  // The face must be flat across the line: a rounded edge's or a tube's is an arc.
  Eigen::Vector3d across = v - n.dot(v) * n;
  if (!(across.squaredNorm() > 1e-12)) return false;
  across.normalize();
  if (!(bend_across(sel, own_plane, across) < kCreaseFlat * prm.sigma * prm.sigma)) return false;
  const Eigen::Vector3d t1 = n.unitOrthogonal(), t2 = n.cross(t1);
  Eigen::Matrix2d c2;
  c2 << t1.dot(c * t1), t1.dot(c * t2), t2.dot(c * t1), t2.dot(c * t2);
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es2(c2);
  KernelFit trial;
  trial.e.col(0) = n;
  trial.e.col(1) = es2.eigenvectors()(0, 0) * t1 + es2.eigenvectors()(1, 0) * t2;
  trial.e.col(2) = es2.eigenvectors()(0, 1) * t1 + es2.eigenvectors()(1, 1) * t2;
  trial.lambda = Eigen::Vector3d(n.dot(c * n), std::max(0.0, es2.eigenvalues()[0]),
                                 std::max(0.0, es2.eigenvalues()[1]));
  trial.cov = trial.e * trial.lambda.asDiagonal() * trial.e.transpose();
  trial.m = m;
  trial.c = centre + m;
  trial.weight = mo.w;
  trial.n = fit.n;  // the caller's (a sensor normal stays)
  fit = trial;
  if (side_out) {
    side_out->b = best.b;
    side_out->p = best.p;
    side_out->own = own == 1;
  }
  return true;
}

bool bends_away(const SampleMoments& moments, const KernelFit& fit) {
  if (moments.n < 3) return false;
  const double limit = kCreaseBend * fit.lambda[0];
  // The smallest eigenvalue is at most the variance along any direction: along the fit's normal
  // first (no eigensolver for most kernels).
  const Eigen::Vector3d n = fit.e.col(0);
  if (!(n.dot(moments.cov * n) > limit)) return false;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
  es.computeDirect(moments.cov, Eigen::EigenvaluesOnly);
  return es.eigenvalues()(0) > limit;
}

}  // namespace scanclean::detail

// The weighted PCA of the kernels (filter/src/kernel_fit.h) against a direct computation with
// Eigen's iterative solver (the oracle), and its trimming of a near outlier; its vector loops
// against their scalar loops.

#include "../../filter/src/kernel_fit.h"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "simd_targets.h"
#include "support/synthetic.h"

namespace scanclean::detail {
namespace {

// The fit holds its samples in float (its sums are in double): samples given in double are
// rounded first. The oracles below get the same rounded values.
FitSample as_float(FitSample q) {
  return {static_cast<float>(q.x), static_cast<float>(q.y), static_cast<float>(q.z),
          static_cast<float>(q.t)};
}

FitSampleSet set_of(const std::vector<FitSample>& s) {
  FitSampleSet set;
  set.assign(s.data(), s.size());
  return set;
}

// Samples on a tilted plane with uniform noise of half-width `noise` along its normal (uniform,
// so that no sample lies beyond the 3-sigma trimming band), chi-weighted for the radius h.
std::vector<FitSample> plane_samples(int n, double h, double noise, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Eigen::Vector3d nrm = Eigen::Vector3d(0.3, -0.2, 1.0).normalized();
  const Eigen::Vector3d t1 = nrm.unitOrthogonal(), t2 = nrm.cross(t1);
  std::vector<FitSample> s;
  while (static_cast<int>(s.size()) < n) {
    const double along_n = u(rng), along_t2 = u(rng), along_t1 = u(rng);  // gcc's order
    const Eigen::Vector3d p = 0.9 * h * (along_t1 * t1 + along_t2 * t2) + noise * along_n * nrm;
    const double r2 = p.squaredNorm();
    if (!(r2 < h * h)) continue;
    double t = 1 - r2 / (h * h);
    t *= t;
    t *= t;
    s.push_back(as_float({p.x(), p.y(), p.z(), t}));
  }
  return s;
}

struct Direct {
  Eigen::Vector3d m;
  Eigen::Matrix3d cov;
  double weight;
};

Direct direct_fit(const std::vector<FitSample>& s) {
  Direct d{Eigen::Vector3d::Zero(), Eigen::Matrix3d::Zero(), 0};
  for (const FitSample& q : s) {
    d.weight += q.t;
    d.m += q.t * Eigen::Vector3d(q.x, q.y, q.z);
  }
  d.m /= d.weight;
  for (const FitSample& q : s) {
    const Eigen::Vector3d r = Eigen::Vector3d(q.x, q.y, q.z) - d.m;
    d.cov += q.t * r * r.transpose();
  }
  d.cov /= d.weight;
  return d;
}

TEST(KernelFitTest, MatchesTheDirectWeightedPca) {
  const double h = 0.01;
  std::vector<FitSample> s = plane_samples(200, h, 0.0004, 11);
  const Direct ref = direct_fit(s);
  const Eigen::Vector3d centre(1.0, 2.0, 3.0);
  KernelFit fit;
  ASSERT_TRUE(fit_samples(s, centre, h, 8, 0.05, fit));
  EXPECT_EQ(s.size(), 200u);  // nothing beyond the trimming band
  EXPECT_NEAR(fit.weight, ref.weight, 1e-12 * ref.weight);
  EXPECT_LT((fit.m - ref.m).norm(), 1e-15);
  EXPECT_LT((fit.c - (centre + ref.m)).norm(), 1e-12);
  EXPECT_LT((fit.cov - ref.cov).norm(), 1e-12 * ref.cov.norm());
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(ref.cov);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(fit.lambda[k], es.eigenvalues()[k], 1e-9 * h * h);
  // The normal is the eigenvector of the smallest eigenvalue (either sign).
  EXPECT_NEAR(std::abs(fit.e.col(0).dot(es.eigenvectors().col(0))), 1.0, 1e-9);
}

TEST(KernelFitTest, TrimsANearOutlierFromTheFit) {
  const double h = 0.01;
  std::vector<FitSample> clean = plane_samples(150, h, 0.0002, 12);
  const Direct ref = direct_fit(clean);
  std::vector<FitSample> s = clean;
  // A point half-way out of the ball, 0.4 h off the plane: far outside 3 standard deviations.
  const Eigen::Vector3d nrm = Eigen::Vector3d(0.3, -0.2, 1.0).normalized();
  const Eigen::Vector3d p = 0.3 * h * nrm.unitOrthogonal() + 0.4 * h * nrm;
  s.push_back(as_float({p.x(), p.y(), p.z(), std::pow(1 - p.squaredNorm() / (h * h), 4)}));
  KernelFit fit;
  ASSERT_TRUE(fit_samples(s, Eigen::Vector3d::Zero(), h, 8, 0.05, fit));
  EXPECT_EQ(s.size(), clean.size());
  EXPECT_LT((fit.cov - ref.cov).norm(), 1e-12 * ref.cov.norm());
}

TEST(KernelFitTest, TrimmedFitsEqualTheDirectPcaOfTheSamplesKept) {
  // Outliers at several distances from the plane, so that trimming takes more than one round
  // (each round's sums are the last round's without the trimmed samples): the fit equals the
  // direct weighted PCA of the samples it kept (the oracle).
  const double h = 0.01;
  std::vector<FitSample> s = plane_samples(250, h, 0.0003, 15);
  const Eigen::Vector3d nrm = Eigen::Vector3d(0.3, -0.2, 1.0).normalized();
  for (int k = 0; k < 6; ++k) {
    const Eigen::Vector3d p =
        (0.1 + 0.1 * k) * h * nrm.unitOrthogonal() + (0.05 + 0.04 * k) * h * nrm;
    s.push_back(as_float({p.x(), p.y(), p.z(), std::pow(1 - p.squaredNorm() / (h * h), 4)}));
  }
  const std::size_t before = s.size();
  KernelFit fit;
  ASSERT_TRUE(fit_samples(s, Eigen::Vector3d::Zero(), h, 8, 0.05, fit));
  EXPECT_LT(s.size(), before);  // something was trimmed
  const Direct ref = direct_fit(s);
  EXPECT_NEAR(fit.weight, ref.weight, 1e-12 * ref.weight);
  EXPECT_LT((fit.m - ref.m).norm(), 1e-12 * h);
  EXPECT_LT((fit.cov - ref.cov).norm(), 1e-10 * ref.cov.norm());
}

TEST(KernelFitTest, TooFewSamplesGiveNoFit) {
  std::vector<FitSample> s = plane_samples(7, 0.01, 0.0002, 13);
  KernelFit fit;
  EXPECT_FALSE(fit_samples(s, Eigen::Vector3d::Zero(), 0.01, 8, 0.05, fit));
  EXPECT_TRUE(fit_samples(s, Eigen::Vector3d::Zero(), 0.01, 7, 0.05, fit));
}

TEST(KernelFitTest, VectorSumsEqualTheScalarLoopBitForBit) {
  // Samples far from the origin and with widely spread weights, so that any change of rounding
  // (order, fused multiply-add) would show in the last bits.
  std::mt19937 rng(14);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (const int n : {0, 1, 3, 8, 15, 97, 250}) {
    std::vector<FitSample> s;
    for (int k = 0; k < n; ++k)
      s.push_back({3.1 + 1e-3 * u(rng), -7.7 + 1e-3 * u(rng), 0.2 + 1e-3 * u(rng),
                   std::pow(0.5 + 0.5 * u(rng), 4)});
    const FitSampleSet set = set_of(s);
    const FitSums v = fit_sums(set);
    const FitSums r = fit_sums_scalar(set);
    const double vs[10] = {v.s0, v.sx, v.sy, v.sz, v.sxx, v.syy, v.szz, v.sxy, v.sxz, v.syz};
    const double rs[10] = {r.s0, r.sx, r.sy, r.sz, r.sxx, r.syy, r.szz, r.sxy, r.sxz, r.syz};
    for (int f = 0; f < 10; ++f) EXPECT_EQ(vs[f], rs[f]) << "n " << n << ", sum " << f;
    if (n > 0) {
      EXPECT_GT(r.sxx, 0.0);
    }
  }
}

TEST(KernelFitTest, SampleMomentsMatchTheDirectUnweightedMoments) {
  // The crease split's first test reads the unweighted mean and covariance of the samples,
  // summed in float lanes: against the same moments summed in double, one sample at a time.
  for (const int n : {1, 7, 8, 9, 250, 1100}) {
    const std::vector<FitSample> s = plane_samples(n, 0.5, 0.02, 17);
    const SampleMoments m = sample_moments(set_of(s));
    ASSERT_EQ(m.n, static_cast<std::size_t>(n));
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const FitSample& q : s) mean += Eigen::Vector3d(q.x, q.y, q.z);
    mean /= n;
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (const FitSample& q : s) {
      const Eigen::Vector3d r = Eigen::Vector3d(q.x, q.y, q.z) - mean;
      cov += r * r.transpose();
    }
    cov /= n;
    EXPECT_LT((m.mean - mean).norm(), 1e-6 * 0.5) << n;
    // Float sums of squares: within 1e-5 of the largest variance (0.5^2 / 3 in the plane).
    EXPECT_LT((m.cov - cov).cwiseAbs().maxCoeff(), 1e-5 * 0.25 / 3) << n;
    EXPECT_EQ(m.cov, m.cov.transpose());
  }
  EXPECT_EQ(sample_moments(FitSampleSet{}).n, 0u);
}

TEST(KernelFitTest, SmallestEigenpairMatchesTheIterativeSolver) {
  // Covariances of planar neighbourhoods (as the kernels see) and of general shapes, rotated at
  // random: the smallest eigenvalue and its vector as Eigen's QR-based solver finds them.
  std::mt19937 rng(19);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int solved = 0, left = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    // Draws in one argument list, written out last to first: gcc's order (test::draw_point).
    const double qz = u(rng), qy = u(rng), qx = u(rng), qw = u(rng);
    const Eigen::Matrix3d rot = Eigen::Quaterniond(qw, qx, qy, qz).normalized().toRotationMatrix();
    const double l1 = trial % 2 == 0 ? 1e-4 * (1 + u(rng)) : 0.05 * (1.5 + u(rng));
    const double l3 = 0.15 + 0.05 * u(rng), l2 = 0.1 + 0.05 * u(rng);
    const Eigen::Vector3d ev(l1, l2, l3);
    const Eigen::Matrix3d c = rot * ev.asDiagonal() * rot.transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> ref(c);
    const double gap = ref.eigenvalues()[1] - ref.eigenvalues()[0];
    const double scale = c.cwiseAbs().maxCoeff();
    double lambda = 0;
    Eigen::Vector3d v;
    const double ratio = ref.eigenvalues()[0] / ref.eigenvalues()[1];
    if (!smallest_eigenpair(c, lambda, v)) {
      // Only smallest pairs within a factor of about 2 are left to the full solver.
      EXPECT_GT(ratio, 0.3) << "trial " << trial;
      ++left;
      continue;
    }
    ++solved;
    // The reference is backward stable (error about 1e-16 scale). The characteristic
    // polynomial's coefficients carry rounding of about 1e-16 scale^3, which moves its root by
    // that over the slope there, gap x scale: up to 800 x 1e-16 scale^2 / gap over 200,000
    // such matrices (8 x without the pairs left to the full solver).
    EXPECT_NEAR(lambda, ref.eigenvalues()[0], 1e-14 + 1e-13 * scale * scale / gap)
        << "trial " << trial;
    EXPECT_NEAR(std::abs(v.dot(ref.eigenvectors().col(0))), 1.0, 1e-12) << "trial " << trial;
    EXPECT_NEAR(v.norm(), 1.0, 1e-15);
  }
  // Every planar case (the kernels' own, the even trials) is solved; of the others, those with
  // the two smallest eigenvalues close are not.
  EXPECT_GE(solved, 1000);
  EXPECT_GT(left, 100);
}

TEST(KernelFitTest, SmallestEigenpairLeavesDegenerateCasesToTheFullSolver) {
  double lambda = -1;
  Eigen::Vector3d v(7, 7, 7);
  EXPECT_FALSE(smallest_eigenpair(Eigen::Matrix3d::Identity(), lambda, v));  // all equal
  EXPECT_FALSE(smallest_eigenpair(Eigen::Matrix3d::Zero(), lambda, v));
  EXPECT_FALSE(smallest_eigenpair(Eigen::Vector3d(0.1, 0.1, 0.3).asDiagonal().toDenseMatrix(),
                                  lambda, v));  // the two smallest equal
  EXPECT_EQ(lambda, -1);
  EXPECT_EQ(v, Eigen::Vector3d(7, 7, 7));
  ASSERT_TRUE(
      smallest_eigenpair(Eigen::Vector3d(0.3, 0.01, 0.2).asDiagonal().toDenseMatrix(), lambda, v));
  EXPECT_NEAR(lambda, 0.01, 1e-16);
  EXPECT_NEAR(std::abs(v.y()), 1.0, 1e-15);
}

TEST(KernelFitTest, VectorSamplesEqualTheScalarLoopBitForBit) {
  // Points around a centre far from the origin, picked in a scrambled order: the same samples,
  // in the same order, bit for bit, on every instruction set. In a cube of half-side 0.025 some
  // are beyond h (blocks stored point by point); in one of 0.01 none is (whole blocks stored).
  std::mt19937 rng(18);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Eigen::Vector3d centre(31.7, -12.25, 4.5);
  const double h = 0.02;
  for (const double half_side : {0.025, 0.01}) {
    SCOPED_TRACE(half_side);
    std::vector<Eigen::Vector3d> p;
    for (int k = 0; k < 300; ++k) p.push_back(centre + half_side * test::draw_point(rng, u, u, u));
    test::for_each_simd_target([&] {
      for (const std::size_t m : {0, 1, 4, 7, 8, 9, 64, 299}) {
        std::vector<std::uint32_t> js(m);
        for (std::size_t k = 0; k < m; ++k) js[k] = static_cast<std::uint32_t>((k * 37) % p.size());
        // Appended after three samples already there.
        FitSampleSet vs = set_of({{1, 2, 3, 4}, {5, 6, 7, 8}, {9, 10, 11, 12}}), rs = vs;
        vs.reserve(vs.n + m);
        rs.reserve(rs.n + m);
        const std::size_t nv = make_samples(p.data(), js.data(), m, centre, h * h, 1 / (h * h), vs);
        const std::size_t nr =
            make_samples_scalar(p.data(), js.data(), m, centre, h * h, 1 / (h * h), rs);
        ASSERT_EQ(nv, nr) << "m " << m;
        ASSERT_EQ(vs.n, 3 + nv);
        ASSERT_EQ(rs.n, 3 + nr);
        std::vector<FitSample> v, r;
        vs.append_to(v);
        rs.append_to(r);
        EXPECT_EQ(v[2].t, 12.0);
        if (m >= 64) {
          EXPECT_GT(nr, 0u);
          if (half_side > h / std::sqrt(3.0))
            EXPECT_LT(nr, m);  // the corners lie beyond h
          else
            EXPECT_EQ(nr, m);
        }
        for (std::size_t k = 3; k < r.size(); ++k) {
          EXPECT_EQ(v[k].x, r[k].x);
          EXPECT_EQ(v[k].y, r[k].y);
          EXPECT_EQ(v[k].z, r[k].z);
          EXPECT_EQ(v[k].t, r[k].t);
          EXPECT_LT(std::sqrt(r[k].x * r[k].x + r[k].y * r[k].y + r[k].z * r[k].z), h * (1 + 1e-6));
        }
      }
    });
  }
}

TEST(KernelFitTest, GatheringFromAnIndexSpanEqualsTheVisitor) {
  // 700 points around point 0 (some beyond h), half of them with sensor normals that face
  // every way: from an array of indices (IndexSpan) the same samples, in the same order, bit
  // for bit, and the same sum of neighbour normals as from a visitor over the same indices;
  // with and without sensor normals in the cloud, oriented or not, at a point with and without
  // a normal of its own. The sets start with stale samples of a larger gather.
  std::mt19937 rng(19);  // seed 19
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double h = 0.02;
  PointSet d;
  d.p.push_back(Eigen::Vector3d(3.5, -1.25, 0.75));
  for (int k = 1; k < 700; ++k) d.p.push_back(d.p[0] + 0.025 * test::draw_point(rng, u, u, u));
  std::vector<std::uint32_t> js;
  for (std::uint32_t k = 0; k < 700; ++k) js.push_back((k * 211) % 700);
  auto normals = [&](bool own) {
    std::vector<Eigen::Vector3f> v(d.p.size(), Eigen::Vector3f::Zero());
    for (std::size_t k = 1; k < v.size(); k += 2)
      v[k] = test::draw_point(rng, u, u, u).cast<float>().normalized();
    if (own) v[0] = Eigen::Vector3f(0, 0, 1);
    return v;
  };
  for (int c = 0; c < 4; ++c) {
    d.v = c == 0 ? std::vector<Eigen::Vector3f>{} : normals(c != 2);
    for (const bool oriented : {false, true})
      for (const std::size_t m : {std::size_t{0}, std::size_t{5}, std::size_t{300}, js.size()}) {
        FitSampleSet a, b;
        gather_samples(d, 0, h, oriented, IndexSpan{js.data(), js.size()}, a);
        gather_samples(d, 0, h, oriented, IndexSpan{js.data(), js.size()}, b);  // stale
        Eigen::Vector3f around_a(9, 9, 9), around_b(7, 7, 7);
        gather_samples(d, 0, h, oriented, IndexSpan{js.data(), m}, a, &around_a);
        gather_samples(
            d, 0, h, oriented,
            [&](auto&& g) {
              for (std::size_t k = 0; k < m; ++k) g(js[k]);
            },
            b, &around_b);
        const std::string at = "case " + std::to_string(c) + " oriented " +
                               std::to_string(oriented) + " m " + std::to_string(m);
        ASSERT_EQ(a.n, b.n) << at;
        if (m == js.size()) {
          EXPECT_GT(a.n, oriented && d.has_v(0) ? 20u : 100u) << at;  // a few face its way
        }
        const std::size_t padded = (a.n + kFitLanes - 1) / kFitLanes * kFitLanes;
        for (std::size_t k = 0; k < padded; ++k) {
          ASSERT_EQ(a.x[k], b.x[k]) << at << " sample " << k;
          ASSERT_EQ(a.y[k], b.y[k]) << at << " sample " << k;
          ASSERT_EQ(a.z[k], b.z[k]) << at << " sample " << k;
          ASSERT_EQ(a.t[k], b.t[k]) << at << " sample " << k;
        }
        EXPECT_EQ(around_a, around_b) << at;
      }
  }
}

TEST(KernelFitTest, VectorTrimmingEqualsTheScalarLoopBitForBit) {
  // A plane with some samples far off it, at the start, in the middle, in the last block and in
  // the tail past the last multiple of eight (and of sixteen): the same samples kept, in the same
  // order, and the same sums left, bit for bit, on every instruction set.
  std::mt19937 rng(16);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  test::for_each_simd_target([&] {
    for (const int n : {0, 3, 4, 9, 16, 17, 24, 64, 251}) {
      for (const int pattern : {0, 1, 2}) {
        std::vector<FitSample> s;
        for (int k = 0; k < n; ++k) {
          const bool off = (pattern == 1 && (k == 0 || k == n / 2 || k == n - 1)) ||
                           (pattern == 2 && k % 3 == 1);
          const double z = (off ? 0.05 : 0.0) + 1e-3 * u(rng);
          s.push_back({0.1 * u(rng), 0.1 * u(rng), z, std::pow(0.5 + 0.5 * u(rng), 4)});
        }
        const TrimPlane plane{{0.01, -0.02, 0.9997499}, {1e-4, -2e-4, 3e-4}, 9 * 1e-6};
        FitSampleSet vset = set_of(s), rset = vset;
        FitSums vs = fit_sums_scalar(vset), rs = vs;
        const std::size_t nv = trim_samples(vset, plane, vs);
        const std::size_t nr = trim_samples_scalar(rset, plane, rs);
        ASSERT_EQ(vset.n, nv);
        std::vector<FitSample> v, r;
        vset.append_to(v);
        rset.append_to(r);
        ASSERT_EQ(nv, nr) << "n " << n << ", pattern " << pattern;
        if (pattern == 1 && n > 0) {
          EXPECT_LT(nr, s.size());
        }
        for (std::size_t k = 0; k < nr; ++k) {
          EXPECT_EQ(v[k].x, r[k].x);
          EXPECT_EQ(v[k].y, r[k].y);
          EXPECT_EQ(v[k].z, r[k].z);
          EXPECT_EQ(v[k].t, r[k].t);
        }
        const double a[10] = {vs.s0,  vs.sx,  vs.sy,  vs.sz,  vs.sxx,
                              vs.syy, vs.szz, vs.sxy, vs.sxz, vs.syz};
        const double b[10] = {rs.s0,  rs.sx,  rs.sy,  rs.sz,  rs.sxx,
                              rs.syy, rs.szz, rs.sxy, rs.sxz, rs.syz};
        for (int f = 0; f < 10; ++f) EXPECT_EQ(a[f], b[f]) << "n " << n << ", sum " << f;
      }
    }
  });
}

TEST(KernelFitTest, TrimmingKeepsExactlyTheSamplesWithinTheLimit) {
  // The oracle: the residual of each sample against the plane, formed directly.
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<FitSample> s;
  for (int k = 0; k < 203; ++k) s.push_back(as_float({u(rng), u(rng), 0.1 * u(rng), 1.0}));
  const TrimPlane plane{{0, 0, 1}, {0, 0, 0.01}, 0.05 * 0.05};
  std::vector<FitSample> expect;
  for (const FitSample& q : s)
    if (std::abs(q.z - 0.01) <= 0.05) expect.push_back(q);
  FitSampleSet set = set_of(s);
  FitSums sums = fit_sums_scalar(set);
  const std::size_t kept = trim_samples(set, plane, sums);
  ASSERT_EQ(kept, expect.size());
  ASSERT_LT(kept, s.size());
  std::vector<FitSample> v;
  set.append_to(v);
  for (std::size_t k = 0; k < kept; ++k) EXPECT_EQ(v[k].z, expect[k].z);
  EXPECT_NEAR(sums.s0, static_cast<double>(kept), 1e-9);
  // The padding past the samples kept is zeros (the vector loops read it).
  for (std::size_t k = kept; k < (kept + kFitLanes - 1) / kFitLanes * kFitLanes; ++k)
    EXPECT_EQ(set.t[k], 0.0f);
}

}  // namespace
}  // namespace scanclean::detail

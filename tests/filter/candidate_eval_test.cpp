// The projection's vectorised inner loops (filter/src/candidate_eval.h) against scalar
// references in double (the oracle): the Mahalanobis distances, the step sums, the likelihood,
// the fast exp, and the transposed append against the one-by-one append.

#include "../../filter/src/candidate_eval.h"
#include "../../filter/src/select.h"

#include <gtest/gtest.h>
#include <hwy/targets.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>

#include "padded_points.h"
#include "simd_targets.h"
#include "support/synthetic.h"

namespace scanclean::detail {
namespace {

// Random kernels around the origin (h = 1 cm): anisotropic, flat, with random normals and weights.
std::vector<KernelRecord> random_kernels(int n, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g(0.0, 1.0);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<KernelRecord> k(n);
  const double h = 0.01;
  for (int j = 0; j < n; ++j) {
    // Each value's draws last to first, as gcc made them in one argument list (test::draw_point).
    const double cz = 0.3 * g(rng), cy = g(rng), cx = g(rng);
    const Eigen::Vector3d c = 0.6 * h * Eigen::Vector3d(cx, cy, cz);
    const double qz = 0.3 * g(rng), qy = 0.3 * g(rng), qx = 0.3 * g(rng), qw = u(rng);
    const Eigen::Matrix3d rot = Eigen::Quaterniond(qw, qx, qy, qz).normalized().matrix();
    const double l2 = std::pow(0.5 * h * (1 + u(rng)), 2), l1 = std::pow(0.4 * h * (1 + u(rng)), 2),
                 l0 = std::pow(0.05 * h * (1 + u(rng)), 2);
    const Eigen::Vector3d lambda(l0, l1, l2);
    const Eigen::Matrix3d s_inv = rot * lambda.cwiseInverse().asDiagonal() * rot.transpose();
    const Eigen::Vector3f n = rot.col(0).cast<float>();
    k[j].set(c, s_inv, n, h * h, static_cast<float>(0.2 + u(rng)), std::sqrt(lambda.maxCoeff()));
  }
  return k;
}

struct Reference {
  std::vector<double> e, d;
  double e_min = std::numeric_limits<double>::infinity();
  double s = 0, dn[3] = {0, 0, 0}, n[3] = {0, 0, 0};
  double likelihood = 0;
};

Reference reference(const std::vector<KernelRecord>& k, const Eigen::Vector3d& x,
                    const Eigen::Vector3d& nref, double t2, double slab2) {
  Reference r;
  for (const KernelRecord& kr : k) {
    const float* f = kr.f;
    const Eigen::Vector3d dx = x - kr.centre().cast<double>();
    const double e =
        f[KernelRecord::kQ00] * dx.x() * dx.x() + f[KernelRecord::kQ11] * dx.y() * dx.y() +
        f[KernelRecord::kQ22] * dx.z() * dx.z() + f[KernelRecord::kQ01] * dx.x() * dx.y() +
        f[KernelRecord::kQ02] * dx.x() * dx.z() + f[KernelRecord::kQ12] * dx.y() * dx.z();
    const double d = kr.normal().cast<double>().dot(dx);
    r.e.push_back(e);
    r.d.push_back(d);
    if (e < t2 && d * d < slab2 * kr.h2()) r.e_min = std::min(r.e_min, e);
    const double slab = kr.h2() - d * d;
    if (e < t2 && slab > 0) r.likelihood += kr.weight() * std::exp(-0.5 * e) * slab;
  }
  for (std::size_t j = 0; j < k.size(); ++j) {
    if (!(r.e[j] < t2 && r.d[j] * r.d[j] < slab2 * k[j].h2())) continue;
    const double om = k[j].weight() * std::exp(-0.5 * (r.e[j] - r.e_min));
    const Eigen::Vector3d n = k[j].normal().cast<double>();
    const double sj = n.dot(nref) < 0 ? -1 : 1;
    r.s += om;
    for (int a = 0; a < 3; ++a) {
      r.dn[a] += om * r.d[j] * n[a];
      r.n[a] += sj * om * n[a];
    }
  }
  return r;
}

TEST(CandidateEvalTest, VectorisedLoopsMatchTheScalarReference) {
  test::for_each_simd_target([&] {
    const float t2 = 9, slab2 = 1;
    for (int trial = 0; trial < 20; ++trial) {
      const int n = 1 + trial * 7;  // 1 to 134 candidates: every padding remainder
      const std::vector<KernelRecord> k = random_kernels(n, 100 + trial);
      std::vector<std::uint32_t> slots(n);
      for (int j = 0; j < n; ++j) slots[j] = static_cast<std::uint32_t>(j);
      const float origin[3] = {0.001f, -0.002f, 0.0005f};
      CandidateBuffer buf;
      buf.clear();
      append_records(buf, k.data(), slots.data(), slots.size(), origin, slab2);
      buf.finish();
      ASSERT_EQ(buf.count, static_cast<std::size_t>(n));
      const Eigen::Vector3d x(0.0012, -0.0009, 0.0003);  // absolute; relative to origin below
      const float xf[3] = {static_cast<float>(x.x() - origin[0]),
                           static_cast<float>(x.y() - origin[1]),
                           static_cast<float>(x.z() - origin[2])};
      const Eigen::Vector3d nref(0, 0, 1);
      const float nref_f[3] = {0, 0, 1};
      const Reference r = reference(k, x, nref, t2, slab2);

      const float e_min_slab = min_mahalanobis(buf, xf);
      double ref_min_slab = std::numeric_limits<double>::infinity();
      for (int j = 0; j < n; ++j)
        if (r.d[j] * r.d[j] < slab2 * k[j].h2()) ref_min_slab = std::min(ref_min_slab, r.e[j]);
      if (std::isfinite(ref_min_slab)) {
        EXPECT_NEAR(e_min_slab, ref_min_slab, 1e-4 * (1 + ref_min_slab)) << "trial " << trial;
      }

      StepSums s;
      const bool kept = step_sums(buf, xf, nref_f, t2, s);
      ASSERT_EQ(kept, std::isfinite(r.e_min)) << "trial " << trial;
      if (kept) {
        EXPECT_NEAR(s.e_min, r.e_min, 1e-4 * (1 + r.e_min));
        EXPECT_NEAR(s.s, r.s, 1e-4 * r.s);
        for (int a = 0; a < 3; ++a) {
          EXPECT_NEAR(s.dn[a], r.dn[a], 1e-4 * r.s * 0.01) << "trial " << trial << " axis " << a;
          EXPECT_NEAR(s.n[a], r.n[a], 1e-4 * r.s) << "trial " << trial << " axis " << a;
        }
        // The likelihood summed with the step (slab 1: the same kernels).
        EXPECT_NEAR(s.likelihood(), r.likelihood, 1e-4 * r.likelihood + 1e-12) << "trial " << trial;
      }
      EXPECT_NEAR(likelihood(buf, xf, t2), r.likelihood, 1e-4 * r.likelihood + 1e-12)
          << "trial " << trial;
    }
  });
}

TEST(CandidateEvalTest, StepAfterMinMahalanobisEqualsAFreshStepBitForBit) {
  test::for_each_simd_target([&] {
    const float t2 = 9, slab2 = 1;
    int kept_trials = 0;
    for (int trial = 0; trial < 20; ++trial) {
      const int n = 1 + trial * 7;
      const std::vector<KernelRecord> k = random_kernels(n, 300 + trial);
      std::vector<std::uint32_t> slots(n);
      for (int j = 0; j < n; ++j) slots[j] = static_cast<std::uint32_t>(j);
      const float origin[3] = {0.002f, 0.001f, -0.0005f};
      CandidateBuffer buf;
      buf.clear();
      append_records(buf, k.data(), slots.data(), slots.size(), origin, slab2);
      buf.finish();
      // Points at and off the kernels, some beyond the truncation of every one.
      const float xf[3] = {0.0004f * static_cast<float>(trial % 5), -0.0007f,
                           0.002f * static_cast<float>(trial % 4)};
      const float nref[3] = {0, 0.6f, 0.8f};
      StepSums fresh, reused;
      const bool kept_fresh = step_sums(buf, xf, nref, t2, fresh);
      min_mahalanobis(buf, xf);
      const bool kept_reused = step_sums_after_min_mahalanobis(buf, nref, t2, reused);
      ASSERT_EQ(kept_fresh, kept_reused) << "trial " << trial;
      if (!kept_fresh) continue;
      ++kept_trials;
      EXPECT_EQ(fresh.e_min, reused.e_min) << "trial " << trial;
      EXPECT_EQ(fresh.s, reused.s) << "trial " << trial;
      EXPECT_EQ(fresh.slab_sum, reused.slab_sum) << "trial " << trial;
      for (int a = 0; a < 3; ++a) {
        EXPECT_EQ(fresh.dn[a], reused.dn[a]) << "trial " << trial << " axis " << a;
        EXPECT_EQ(fresh.n[a], reused.n[a]) << "trial " << trial << " axis " << a;
      }
    }
    EXPECT_GT(kept_trials, 5);  // the comparison was made, not skipped
  });
}

// AVX-512 runs the loops without sums 16 lanes wide and the sums in 8 lanes, as AVX2 does: the
// two give the same step, bit for bit (the filter's output does not depend on the processor).
TEST(CandidateEvalTest, AvxTargetsGiveTheSameStepBitForBit) {
  const float t2 = 9, slab2 = 1;
  for (int trial = 0; trial < 20; ++trial) {
    const int n = 1 + trial * 7;  // padded to 8 .. 136: with and without a last 8 lanes
    const std::vector<KernelRecord> k = random_kernels(n, 500 + trial);
    std::vector<std::uint32_t> slots(n);
    for (int j = 0; j < n; ++j) slots[j] = static_cast<std::uint32_t>(j);
    const float origin[3] = {0.001f, 0.0f, -0.001f};
    const float xf[3] = {0.0003f * static_cast<float>(trial % 3), 0.0005f, -0.0004f};
    const float nref[3] = {0, 0, 1};
    std::vector<std::pair<StepSums, float>> got;
    for (const std::int64_t target : hwy::SupportedAndGeneratedTargets()) {
      if (!(target & (HWY_AVX3_DL | HWY_AVX3 | HWY_AVX2))) continue;
      hwy::SetSupportedTargetsForTest(target);
      CandidateBuffer buf;
      buf.clear();
      append_records(buf, k.data(), slots.data(), slots.size(), origin, slab2);
      buf.finish();
      StepSums s;
      if (!step_sums(buf, xf, nref, t2, s)) s = StepSums{};
      got.emplace_back(s, min_mahalanobis(buf, xf));
    }
    hwy::SetSupportedTargetsForTest(0);
    for (std::size_t t = 1; t < got.size(); ++t) {
      EXPECT_EQ(got[t].first.e_min, got[0].first.e_min) << "trial " << trial;
      EXPECT_EQ(got[t].first.s, got[0].first.s) << "trial " << trial;
      EXPECT_EQ(got[t].first.slab_sum, got[0].first.slab_sum) << "trial " << trial;
      for (int a = 0; a < 3; ++a) {
        EXPECT_EQ(got[t].first.dn[a], got[0].first.dn[a]) << "trial " << trial;
        EXPECT_EQ(got[t].first.n[a], got[0].first.n[a]) << "trial " << trial;
      }
      EXPECT_EQ(got[t].second, got[0].second) << "trial " << trial;
    }
  }
}

// The step's sums in 8 lanes (AVX2, AVX-512), emulated in scalar float operations: candidate j
// in lane j mod 8, its terms added in candidate order (std::fma where the loop multiply-adds),
// each lane's partial sums then added in double in lane order. The loop takes two vectors of
// candidates at a time where it can; the sums must not depend on that, bit for bit. The e_j
// and d_j are the ones the step stored in the buffer.
TEST(CandidateEvalTest, StepSumsEqualALaneByLaneEmulationBitForBit) {
  using B = CandidateBuffer;
  const float t2 = 9, slab2 = 1;
  int compared = 0;
  for (const std::int64_t target : hwy::SupportedAndGeneratedTargets()) {
    if (!(target & (HWY_AVX3_DL | HWY_AVX3 | HWY_AVX2))) continue;
    hwy::SetSupportedTargetsForTest(target);
    for (int trial = 0; trial < 24; ++trial) {
      const int n = 1 + trial * 6;  // 1 to 139 candidates: odd and even counts of vectors
      const std::vector<KernelRecord> k = random_kernels(n, 900 + trial);
      std::vector<std::uint32_t> slots(n);
      for (int j = 0; j < n; ++j) slots[j] = static_cast<std::uint32_t>(j);
      const float origin[3] = {-0.001f, 0.0005f, 0.0f};
      const float xf[3] = {0.0004f * static_cast<float>(trial % 4), -0.0003f, 0.0002f};
      const float nref[3] = {0.6f, 0.0f, 0.8f};
      CandidateBuffer buf;
      buf.clear();
      append_records(buf, k.data(), slots.data(), slots.size(), origin, slab2);
      buf.finish();
      StepSums s;
      if (!step_sums(buf, xf, nref, t2, s)) continue;
      const float inf = std::numeric_limits<float>::infinity();
      float lane[8][8] = {};  // [sum][lane]: s, dn x y z, n x y z, slab
      for (std::size_t j = 0; j < buf.padded; ++j) {
        const float em = buf.f[B::kE][j], dist = buf.d[j];
        const float a = std::max((s.e_min - em) * 0.5f, -80.0f);
        const float om = em < inf ? buf.f[B::kW][j] * fast_exp(a) : 0.0f;
        const float nx = buf.f[B::kNx][j], ny = buf.f[B::kNy][j], nz = buf.f[B::kNz][j];
        const float od = om * dist;
        const float sj = std::fma(nz, nref[2], std::fma(ny, nref[1], nx * nref[0]));
        const float os = sj < 0 ? -om : om;
        const float slab = std::fma(-dist, dist, buf.f[B::kH2][j]);
        const std::size_t l = j % 8;
        lane[0][l] += om;
        lane[1][l] = std::fma(od, nx, lane[1][l]);
        lane[2][l] = std::fma(od, ny, lane[2][l]);
        lane[3][l] = std::fma(od, nz, lane[3][l]);
        lane[4][l] = std::fma(os, nx, lane[4][l]);
        lane[5][l] = std::fma(os, ny, lane[5][l]);
        lane[6][l] = std::fma(os, nz, lane[6][l]);
        lane[7][l] += slab > 0 ? om * slab : 0.0f;
      }
      double sum[8] = {};
      for (int m = 0; m < 8; ++m)
        for (int l = 0; l < 8; ++l) sum[m] += lane[m][l];
      EXPECT_EQ(s.s, sum[0]) << "trial " << trial;
      for (int a = 0; a < 3; ++a) {
        EXPECT_EQ(s.dn[a], sum[1 + a]) << "trial " << trial << " axis " << a;
        EXPECT_EQ(s.n[a], sum[4 + a]) << "trial " << trial << " axis " << a;
      }
      EXPECT_EQ(s.slab_sum, sum[7]) << "trial " << trial;
      ++compared;
    }
  }
  hwy::SetSupportedTargetsForTest(0);
  if (compared == 0) GTEST_SKIP() << "no AVX2 or AVX-512 target on this processor";
  EXPECT_GT(compared, 20);  // the comparisons were made, not skipped
}

TEST(CandidateEvalTest, KernelsBeyondTheirReachAddNothing) {
  test::for_each_simd_target([&] {
    // The oracle: the step sums over every kernel. Dropping the kernels farther from the gather
    // origin than 3.03 sigma_j + margin (select_within_reach, as the projection's regathers do)
    // changes no sum beyond rounding, for points anywhere within the margin.
    const float t2 = 9, slab2 = 1, scale = 3.03f, margin = 0.00125f;  // h / 8 at h = 1 cm
    std::mt19937 rng(31);                                             // seed 31
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    std::size_t dropped = 0, total = 0;
    for (int trial = 0; trial < 20; ++trial) {
      const int n = 150;
      std::vector<KernelRecord> k = random_kernels(n, 500 + trial);
      for (KernelRecord& r : k)  // spread the centres (2.4 h) beyond most kernels' reach
        for (std::size_t a = KernelRecord::kCx; a <= KernelRecord::kCz; ++a) r.f[a] *= 4;
      const float origin[3] = {0.003f * u(rng), 0.003f * u(rng), 0.0005f * u(rng)};
      std::vector<float> x(n), y(n), z(n), sigma(n);
      std::vector<std::uint32_t> all(n), kept(n + 8);
      for (int j = 0; j < n; ++j) {
        x[j] = k[j].f[KernelRecord::kCx];
        y[j] = k[j].f[KernelRecord::kCy];
        z[j] = k[j].f[KernelRecord::kCz];
        sigma[j] = k[j].sigma();
        all[j] = static_cast<std::uint32_t>(j);
      }
      test::pad_at_infinity(x, y, z, all, 0, &sigma, 0);
      const std::size_t m =
          select_within_reach(x.data(), y.data(), z.data(), sigma.data(), all.data(), x.size(),
                              origin, 1.0f, scale, margin, kept.data());
      dropped += static_cast<std::size_t>(n) - m;
      total += static_cast<std::size_t>(n);
      CandidateBuffer every, reached;
      every.clear();
      reached.clear();
      append_records(every, k.data(), all.data(), static_cast<std::size_t>(n), origin, slab2);
      append_records(reached, k.data(), kept.data(), m, origin, slab2);
      every.finish();
      reached.finish();
      const float nref[3] = {0, 0, 1};
      for (int p = 0; p < 10; ++p) {
        Eigen::Vector3f d = test::draw_point(rng, u, u, u).cast<float>();
        d *= 0.999f * margin / std::max(d.norm(), 1e-6f) * std::abs(u(rng));
        const float xf[3] = {d.x(), d.y(), d.z()};
        StepSums a, b;
        const bool ka = step_sums(every, xf, nref, t2, a), kb = step_sums(reached, xf, nref, t2, b);
        ASSERT_EQ(ka, kb) << "trial " << trial;
        if (!ka) continue;
        EXPECT_EQ(a.e_min, b.e_min);
        EXPECT_NEAR(a.s, b.s, 1e-6 * a.s);
        for (int ax = 0; ax < 3; ++ax) {
          EXPECT_NEAR(a.dn[ax], b.dn[ax], 1e-6 * a.s * 0.01);
          EXPECT_NEAR(a.n[ax], b.n[ax], 1e-6 * a.s);
        }
        EXPECT_NEAR(a.likelihood(), b.likelihood(), 1e-6 * a.likelihood() + 1e-15);
      }
    }
    EXPECT_GT(dropped, total / 3);  // the filter does drop kernels here
  });
}

TEST(CandidateEvalTest, TransposedAppendEqualsAppendingOneByOne) {
  // On every target (AVX-512 transposes 16-float records a vector each, AVX2 two halves each,
  // the others append one by one), in two appends to the same buffer: the second starts at a
  // count that is not a multiple of 8.
  const std::vector<KernelRecord> k = random_kernels(37, 7);
  std::vector<std::uint32_t> slots;
  for (std::uint32_t j = 0; j < 37; j += 2) slots.push_back(j);  // a scattered selection
  for (std::uint32_t j = 1; j < 37; j += 4) slots.push_back(j);
  const float origin[3] = {0.5f, -0.25f, 2.0f};
  test::for_each_simd_target([&] {
    CandidateBuffer a, b;
    a.clear();
    b.clear();
    const std::size_t first = 11;
    append_records(a, k.data(), slots.data(), first, origin, 1.5f);
    append_records(a, k.data(), slots.data() + first, slots.size() - first, origin, 1.5f);
    for (std::uint32_t s : slots) b.push_record(s, k[s], origin, 1.5f);
    a.finish();
    b.finish();
    ASSERT_EQ(a.count, b.count);
    for (std::size_t j = 0; j < a.count; ++j) {
      EXPECT_EQ(a.slot[j], b.slot[j]);
      for (std::size_t f = 0; f < CandidateBuffer::kE; ++f) EXPECT_EQ(a.f[f][j], b.f[f][j]) << f;
    }
  });
}

TEST(CandidateEvalTest, FirstCandidateWithEIsTheFirstThatEqualsIt) {
  // The oracle: a plain search over the buffer's e_j. Each value is asked for, with some repeated
  // further on (the first one counts) and in every lane of a vector, on every target; a value
  // that is not there gives the last candidate.
  const std::vector<KernelRecord> k = random_kernels(37, 9);
  std::vector<std::uint32_t> slots(k.size());
  for (std::uint32_t j = 0; j < slots.size(); ++j) slots[j] = j;
  const float origin[3] = {0, 0, 0}, x[3] = {0.001f, -0.002f, 0.0005f};
  test::for_each_simd_target([&] {
    CandidateBuffer buf;
    buf.clear();
    append_records(buf, k.data(), slots.data(), slots.size(), origin, 1.0f);
    buf.finish();
    min_mahalanobis(buf, x);
    float* e = buf.f[CandidateBuffer::kE].data();
    e[20] = e[3];
    e[36] = e[17];
    for (std::size_t j = 0; j < buf.count; ++j) {
      std::size_t first = 0;
      while (e[first] != e[j]) ++first;
      ASSERT_EQ(first_candidate_with_e(buf, e[j]), first) << "candidate " << j;
    }
    EXPECT_EQ(first_candidate_with_e(buf, e[3]), 3u);
    EXPECT_EQ(first_candidate_with_e(buf, -1.0f), buf.count - 1);
  });
}

TEST(CandidateEvalTest, FastExpIsAccurateOverItsRange) {
  test::for_each_simd_target([&] {
    // The loops evaluate exp at -e_j / 2 > -4.5 (truncation at 3 sigma) and at differences of such
    // values; the floor is -80. Past the polynomial's error, float rounding of a log2(e) grows with
    // |a|.
    double near = 0, far = 0;
    for (int k = 0; k <= 8000; ++k) {
      const float a = -80.0f * static_cast<float>(k) / 8000.0f;
      const double rel = std::abs(fast_exp(a) - std::exp(static_cast<double>(a))) / std::exp(a);
      (a >= -10.0f ? near : far) = std::max(a >= -10.0f ? near : far, rel);
    }
    std::printf("fast_exp: max relative error %.3g on [-10, 0], %.3g on [-80, -10)\n", near, far);
    EXPECT_LT(near, 1e-6);
    EXPECT_LT(far, 5e-6);
  });
}

}  // namespace
}  // namespace scanclean::detail

// kth_smallest_below (filter/src/select.h) against std::nth_element, the oracle: random values,
// ties, values outside the stated range; the band, within and near-box counts and the
// selections by distance against plain loops, on every vector target (simd_targets.h); the
// float bound of a double test against the test itself.

#include "../../filter/src/select.h"

#include <gtest/gtest.h>

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "padded_points.h"
#include "simd_targets.h"
#include "support/synthetic.h"

namespace scanclean::detail {
namespace {

// Oracle: std::nth_element on a copy.
float nth(std::vector<float> v, std::size_t k) {
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

TEST(SelectTest, MatchesNthElementOnRandomValues) {
  std::mt19937 rng(61);  // seed 61
  for (int trial = 0; trial < 400; ++trial) {
    const std::size_t n = 1 + rng() % 600;
    const float upper = 0.5f + static_cast<float>(rng() % 1000) * 0.01f;
    // Squared distances of points in a disc (dense towards upper), with some repeated values.
    std::uniform_real_distribution<float> u(0.0f, upper);
    std::vector<float> v(n);
    for (auto& x : v) x = trial % 3 == 0 ? u(rng) : std::max(u(rng), u(rng));
    for (std::size_t i = 0; i + 1 < n; i += 7) v[i + 1] = v[i];
    const std::size_t k = rng() % n;
    std::vector<float> scratch = v;
    EXPECT_EQ(kth_smallest_below(scratch.data(), n, k, upper), nth(v, k))
        << "trial " << trial << " n " << n << " k " << k;
  }
}

TEST(SelectTest, ExactWithTiesAndValuesOutsideTheRange) {
  // All equal; clustered in one bin; values below 0 and at or above `upper` (end bins).
  std::vector<float> equal(300, 0.25f);
  for (std::size_t k : {0u, 150u, 299u}) {
    std::vector<float> s = equal;
    EXPECT_EQ(kth_smallest_below(s.data(), s.size(), k, 1.0f), 0.25f);
  }
  std::mt19937 rng(62);  // seed 62
  std::uniform_real_distribution<float> u(-0.5f, 1.5f);
  std::vector<float> v(500);
  for (auto& x : v) x = u(rng);
  for (std::size_t k = 0; k < v.size(); k += 37) {
    std::vector<float> s = v;
    EXPECT_EQ(kth_smallest_below(s.data(), s.size(), k, 1.0f), nth(v, k)) << k;
  }
  std::vector<float> s = v;  // upper <= 0: plain selection
  EXPECT_EQ(kth_smallest_below(s.data(), s.size(), 10, 0.0f), nth(v, 10));
}

// count_below_and_band against a plain loop over the same float arithmetic: random points
// around q, counts of every length (the vector body and its scalar tail), bounds on values.
TEST(SelectTest, SmallSelectionByCountingMatchesNthElement) {
  test::for_each_simd_target([&] {
    // Every size up to kSmallSelect (whole vectors and tails), every rank, with ties.
    std::mt19937 rng(71);  // seed 71
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    for (std::size_t n = 1; n <= kSmallSelect; ++n) {
      std::vector<float> v(n);
      for (auto& x : v) x = u(rng);
      for (std::size_t i = 0; i + 2 < n; i += 5) v[i + 2] = v[i];
      for (std::size_t k = 0; k < n; ++k) {
        std::vector<float> scratch = v;
        EXPECT_EQ(kth_smallest_small(scratch.data(), n, k), nth(v, k)) << "n " << n << " k " << k;
      }
    }
    std::vector<float> equal(40, 0.5f);
    EXPECT_EQ(kth_smallest_small(equal.data(), equal.size(), 17), 0.5f);
  });
}

TEST(SelectTest, BetweenMatchesNthElementOnSignedValues) {
  // Moves along the normal (signed, Gaussian, offset) over their own range, as the displacement
  // test selects them: the median, then the median absolute deviation, each as nth_element. On
  // every vector target (the bins and the kept bin's values are vector loops), sizes with and
  // without a tail; some trials hold infinities, which go to the end bins.
  test::for_each_simd_target([&] {
    std::mt19937 rng(67);  // seed 67
    std::normal_distribution<float> g(0.0f, 1.0f);
    const float inf = std::numeric_limits<float>::infinity();
    for (int trial = 0; trial < 400; ++trial) {
      const std::size_t n = 8 + rng() % 400;
      std::vector<float> v(n);
      for (auto& x : v) x = 0.01f * g(rng) + 0.003f;
      for (std::size_t i = 0; i + 1 < n; i += 11) v[i + 1] = v[i];
      const float lo = *std::min_element(v.begin(), v.end());
      const float hi = *std::max_element(v.begin(), v.end());
      if (trial % 5 == 0) {
        v[rng() % n] = inf;
        v[rng() % n] = -inf;
      }
      std::vector<float> scratch = v;
      const float median = kth_smallest_between(scratch.data(), n, n / 2, lo, hi);
      ASSERT_EQ(median, nth(v, n / 2)) << "trial " << trial << " n " << n;
      std::vector<float> dev(n);
      for (std::size_t i = 0; i < n; ++i) dev[i] = std::abs(v[i] - median);
      scratch = dev;
      EXPECT_EQ(kth_smallest_below(scratch.data(), n, n / 2, std::max(hi - median, median - lo)),
                nth(dev, n / 2))
          << "trial " << trial << " n " << n;
      // A narrower stated range: values outside it go to the end bins, still exact.
      for (std::size_t k : {std::size_t{0}, n / 3, n - 1}) {
        scratch = v;
        EXPECT_EQ(kth_smallest_between(scratch.data(), n, k, lo / 2, hi / 2), nth(v, k));
      }
    }
    std::vector<float> equal(100, -0.5f);  // an empty range: plain selection
    EXPECT_EQ(kth_smallest_between(equal.data(), equal.size(), 40, -0.5f, -0.5f), -0.5f);
  });
}

TEST(SelectTest, BandCountsMatchAPlainLoopAndBracketTheKthDistance) {
  test::for_each_simd_target([&] {
    std::mt19937 rng(63);  // seed 63
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    for (int trial = 0; trial < 200; ++trial) {
      const std::size_t n =
          static_cast<std::size_t>(trial % 41) + static_cast<std::size_t>(rng() % 300);
      std::vector<float> x(n), y(n), z(n);
      for (std::size_t j = 0; j < n; ++j) {
        x[j] = u(rng);
        y[j] = u(rng);
        z[j] = 0.1f * u(rng);
      }
      if (n > 3) x[1] = x[0], y[1] = y[0], z[1] = z[0];  // a tie
      const float q[3] = {0.1f * u(rng), 0.1f * u(rng), 0.0f};
      const float lo2 = 0.2f + 0.2f * (u(rng) + 1), up2 = lo2 + 0.3f * (u(rng) + 1);
      std::vector<float> all(n);
      std::size_t want_below = 0;
      std::vector<float> want_band;
      for (std::size_t j = 0; j < n; ++j) {
        const float dx = x[j] - q[0], dy = y[j] - q[1], dz = z[j] - q[2];
        all[j] = dx * dx + dy * dy + dz * dz;
        if (all[j] < lo2)
          ++want_below;
        else if (all[j] < up2)
          want_band.push_back(all[j]);
      }
      std::size_t below = 5, m = 3;  // both add to what is there
      std::vector<float> band(m + n + kStoreSlack, -1.0f);
      count_below_and_band(x.data(), y.data(), z.data(), n, q, lo2, up2, below, band.data(), m);
      ASSERT_EQ(below, 5 + want_below) << trial;
      ASSERT_EQ(m, 3 + want_band.size()) << trial;
      EXPECT_TRUE(std::equal(want_band.begin(), want_band.end(), band.begin() + 3)) << trial;
      // A band that brackets rank k holds the k-th smallest of all.
      const std::size_t k = want_below + want_band.size() / 2;
      if (want_band.empty() || k >= n) continue;
      std::vector<float> b(band.begin() + 3, band.begin() + static_cast<std::ptrdiff_t>(m));
      EXPECT_EQ(nth(b, k - want_below), nth(all, k)) << trial;
    }
  });
}

TEST(SelectTest, CountWithinMatchesAPlainLoop) {
  test::for_each_simd_target([&] {
    // The oracle: the scalar loop over every point, with the same rounding of the distances.
    std::mt19937 rng(23);  // seed 23
    std::uniform_real_distribution<float> u(-1.0f, 1.0f), l(0.0f, 2.0f);
    std::uniform_int_distribution<std::uint32_t> c(1, 40);
    for (std::size_t n : {0, 5, 8, 61, 300}) {
      std::vector<float> x(n), y(n), z(n), lik(n);
      std::vector<std::uint32_t> cnt(n);
      for (std::size_t j = 0; j < n; ++j) {
        x[j] = u(rng);
        y[j] = u(rng);
        z[j] = u(rng);
        lik[j] = l(rng);
        cnt[j] = c(rng);
      }
      if (n > 3) lik[3] = 1.0f;  // a likelihood at the bound itself counts
      const float q[3] = {0.1f, -0.2f, 0.05f}, r2 = 0.49f, lik_max = 1.0f;
      std::uint64_t sum = 0;
      std::size_t within = 0, below = 0;
      for (std::size_t j = 0; j < n; ++j) {
        const float dx = x[j] - q[0], dy = y[j] - q[1], dz = z[j] - q[2];
        if (!(dx * dx + dy * dy + dz * dz < r2)) continue;
        sum += cnt[j];
        ++within;
        below += lik[j] <= lik_max ? 1 : 0;
      }
      WithinCounts w;
      count_within(x.data(), y.data(), z.data(), cnt.data(), lik.data(), n, q, r2, lik_max, w);
      EXPECT_EQ(w.sum, sum) << n;
      EXPECT_EQ(w.n, within) << n;
      EXPECT_EQ(w.at_or_below, below) << n;
      if (n >= 61) {
        EXPECT_GT(within, 0u);
      }
      WithinCounts no_lik;  // without likelihoods: the same sum and number, none at or below
      count_within(x.data(), y.data(), z.data(), cnt.data(), nullptr, n, q, r2, lik_max, no_lik);
      EXPECT_EQ(no_lik.sum, sum);
      EXPECT_EQ(no_lik.n, within);
      EXPECT_EQ(no_lik.at_or_below, 0u);
    }
  });
}

TEST(SelectTest, NearBoxKeepsEveryPointWithinReachOfAQueryInTheBox) {
  test::for_each_simd_target([&] {
    // The oracle: a plain loop over the points with the same float rounding of the gaps; and the
    // invariant the adaptive scale relies on: a point whose squared distance (rounded as
    // count_below_and_band rounds it) to a query inside the box is below r2 is always kept.
    std::mt19937 rng(29);  // seed 29
    std::uniform_real_distribution<float> u(-1.0f, 1.0f), in(0.0f, 1.0f);
    for (std::size_t n : {0, 3, 8, 13, 64, 301}) {
      for (int trial = 0; trial < 20; ++trial) {
        std::vector<float> x(n), y(n), z(n);
        for (std::size_t j = 0; j < n; ++j) {
          x[j] = u(rng);
          y[j] = u(rng);
          z[j] = u(rng);
        }
        const float lo[3] = {-0.2f, -0.1f, 0.0f}, hi[3] = {0.1f, 0.25f, 0.05f};
        const float r2 = 0.3f * 0.3f;
        std::vector<float> ox(2 + n + kStoreSlack), oy(2 + n + kStoreSlack),
            oz(2 + n + kStoreSlack);
        std::size_t m = 2;  // appends after what is there
        // With the slots and extra values carried along.
        std::vector<std::uint32_t> sl(n), osl(2 + n + kStoreSlack);
        std::vector<float> extra(n), oex(2 + n + kStoreSlack);
        for (std::size_t j = 0; j < n; ++j) {
          sl[j] = static_cast<std::uint32_t>(5 * j + 1);
          extra[j] = 0.5f * static_cast<float>(j);
        }
        select_near_box(x.data(), y.data(), z.data(), sl.data(), extra.data(), n, lo, hi, r2,
                        {ox.data(), oy.data(), oz.data(), osl.data(), oex.data()}, m);
        std::vector<float> wx, wy, wz, wex;
        std::vector<std::uint32_t> wsl;
        for (std::size_t j = 0; j < n; ++j) {
          const float ex = std::max(std::max(lo[0] - x[j], x[j] - hi[0]), 0.0f);
          const float ey = std::max(std::max(lo[1] - y[j], y[j] - hi[1]), 0.0f);
          const float ez = std::max(std::max(lo[2] - z[j], z[j] - hi[2]), 0.0f);
          if (ex * ex + ey * ey + ez * ez < r2) {
            wx.push_back(x[j]);
            wy.push_back(y[j]);
            wz.push_back(z[j]);
            wsl.push_back(sl[j]);
            wex.push_back(extra[j]);
          }
        }
        ASSERT_EQ(m, 2 + wx.size()) << "n " << n;
        for (std::size_t k = 0; k < wx.size(); ++k) {
          ASSERT_EQ(ox[2 + k], wx[k]);
          ASSERT_EQ(oy[2 + k], wy[k]);
          ASSERT_EQ(oz[2 + k], wz[k]);
          ASSERT_EQ(osl[2 + k], wsl[k]);
          ASSERT_EQ(oex[2 + k], wex[k]);
        }
        // Queries inside the box: every point the band count would see below r2 is kept.
        for (int qi = 0; qi < 8; ++qi) {
          const float q[3] = {lo[0] + in(rng) * (hi[0] - lo[0]), lo[1] + in(rng) * (hi[1] - lo[1]),
                              lo[2] + in(rng) * (hi[2] - lo[2])};
          std::size_t below_all = 0, below_kept = 0, m_all = 0, m_kept = 0;
          std::vector<float> band(n + m + kStoreSlack);
          count_below_and_band(x.data(), y.data(), z.data(), n, q, r2, r2, below_all, band.data(),
                               m_all);
          count_below_and_band(ox.data() + 2, oy.data() + 2, oz.data() + 2, m - 2, q, r2, r2,
                               below_kept, band.data(), m_kept);
          EXPECT_EQ(below_kept, below_all) << "n " << n << " query " << qi;
        }
      }
    }
  });
}

TEST(SelectTest, SelectWithinEqualsTheScalarDistanceTest) {
  // 203 points pad to 208 (13 vectors of 16), 195 to 200 (12 of 16 and one of 8).
  for (const int count : {203, 195})
    test::for_each_simd_target([&] {
      // Points around a sphere of radius r (many within a few ulps of it), padded with +inf.
      std::mt19937 rng(21);
      std::normal_distribution<float> g(0.0f, 1.0f);
      std::uniform_real_distribution<float> u(0.999f, 1.001f);
      const float origin[3] = {0.31f, -0.12f, 0.05f};
      const float r = 0.0125f, r2 = r * r;
      std::vector<float> x, y, z;
      std::vector<std::uint32_t> slots;
      for (int j = 0; j < count; ++j) {
        Eigen::Vector3f v = test::draw_point(rng, g, g, g).cast<float>();
        v *= r * u(rng) / v.norm();
        x.push_back(origin[0] + v.x());
        y.push_back(origin[1] + v.y());
        z.push_back(origin[2] + v.z());
        slots.push_back(static_cast<std::uint32_t>(1000 + 3 * j));
      }
      std::vector<std::uint32_t> expected;
      for (std::size_t j = 0; j < x.size(); ++j) {
        const float dx = x[j] - origin[0], dy = y[j] - origin[1], dz = z[j] - origin[2];
        const float d2 = dx * dx + dy * dy;
        if (d2 + dz * dz < r2) expected.push_back(slots[j]);
      }
      test::pad_at_infinity(x, y, z, slots, 7);
      std::vector<std::uint32_t> out(x.size());
      const std::size_t n = select_within(x.data(), y.data(), z.data(), slots.data(), x.size(),
                                          origin, r2, out.data());
      out.resize(n);
      EXPECT_EQ(out, expected);
      EXPECT_GT(expected.size(), 50u);  // both sides of the sphere are present
      EXPECT_LT(expected.size(), 150u);
    });
}

TEST(SelectTest, SelectWithinReachEqualsTheScalarTests) {
  // 301 points pad to 304 (19 vectors of 16), 293 to 296 (18 of 16 and one of 8).
  for (const std::uint32_t count : {301u, 293u})
    test::for_each_simd_target([&] {
      // Both tests, in float without fused multiply-add, against a plain loop; padding at infinity.
      std::mt19937 rng(33);  // seed 33
      std::uniform_real_distribution<float> u(-1.0f, 1.0f), s(0.0f, 0.5f);
      const float origin[3] = {0.1f, 0.2f, -0.1f}, r2 = 0.5f, scale = 3.03f, margin = 0.05f;
      std::vector<float> x, y, z, sigma;
      std::vector<std::uint32_t> slots, expected;
      for (std::uint32_t j = 0; j < count; ++j) {
        x.push_back(origin[0] + u(rng));
        y.push_back(origin[1] + u(rng));
        z.push_back(origin[2] + 0.3f * u(rng));
        sigma.push_back(s(rng));
        slots.push_back(7 * j + 1);
        const float dx = x[j] - origin[0], dy = y[j] - origin[1], dz = z[j] - origin[2];
        const float d2 = dx * dx + dy * dy;
        const float reach = scale * sigma[j] + margin;
        if (d2 + dz * dz < r2 && d2 + dz * dz < reach * reach) expected.push_back(slots[j]);
      }
      test::pad_at_infinity(x, y, z, slots, 3, &sigma, 1);
      std::vector<std::uint32_t> out(x.size());
      out.resize(select_within_reach(x.data(), y.data(), z.data(), sigma.data(), slots.data(),
                                     x.size(), origin, r2, scale, margin, out.data()));
      EXPECT_EQ(out, expected);
      EXPECT_GT(expected.size(), 20u);
      EXPECT_LT(expected.size(), 250u);
    });
}

TEST(SelectTest, LoopsTakenOnceGiveTheFreeFunctionsResults) {
  // select_loops() hands out the same target's loops as the free functions dispatch to.
  test::for_each_simd_target([&] {
    const SelectLoops loops = select_loops();
    std::mt19937 rng(37);  // seed 37
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    const std::size_t n = 45;
    std::vector<float> x(n), y(n), z(n), lik(n);
    std::vector<std::uint32_t> cnt(n);
    for (std::size_t j = 0; j < n; ++j) {
      x[j] = u(rng);
      y[j] = u(rng);
      z[j] = u(rng);
      lik[j] = u(rng);
      cnt[j] = static_cast<std::uint32_t>(j % 7 + 1);
    }
    const float q[3] = {0.1f, 0.0f, -0.1f};
    std::size_t below_a = 0, below_b = 0, m_a = 0, m_b = 0;
    std::vector<float> band_a(n + kStoreSlack), band_b(n + kStoreSlack);
    loops.count_below_and_band(x.data(), y.data(), z.data(), n, q, 0.3f, 0.9f, below_a,
                               band_a.data(), m_a);
    count_below_and_band(x.data(), y.data(), z.data(), n, q, 0.3f, 0.9f, below_b, band_b.data(),
                         m_b);
    EXPECT_EQ(below_a, below_b);
    ASSERT_EQ(m_a, m_b);
    EXPECT_GT(m_a, 0u);
    EXPECT_TRUE(std::equal(band_a.begin(), band_a.begin() + static_cast<std::ptrdiff_t>(m_a),
                           band_b.begin()));
    WithinCounts wa, wb;
    loops.count_within(x.data(), y.data(), z.data(), cnt.data(), lik.data(), n, q, 0.5f, 0.0f, wa);
    count_within(x.data(), y.data(), z.data(), cnt.data(), lik.data(), n, q, 0.5f, 0.0f, wb);
    EXPECT_EQ(wa.sum, wb.sum);
    EXPECT_EQ(wa.n, wb.n);
    EXPECT_EQ(wa.at_or_below, wb.at_or_below);
    const float lo[3] = {-0.1f, -0.1f, -0.1f}, hi[3] = {0.1f, 0.1f, 0.1f};
    std::vector<float> ax(n + kStoreSlack), ay(n + kStoreSlack), az(n + kStoreSlack),
        bx(n + kStoreSlack), by(n + kStoreSlack), bz(n + kStoreSlack);
    std::size_t na = 0, nb = 0;
    loops.select_near_box(x.data(), y.data(), z.data(), nullptr, nullptr, n, lo, hi, 0.25f,
                          {ax.data(), ay.data(), az.data()}, na);
    select_near_box(x.data(), y.data(), z.data(), nullptr, nullptr, n, lo, hi, 0.25f,
                    {bx.data(), by.data(), bz.data()}, nb);
    ASSERT_EQ(na, nb);
    EXPECT_GT(na, 0u);
    EXPECT_TRUE(std::equal(ax.begin(), ax.begin() + static_cast<std::ptrdiff_t>(na), bx.begin()));
  });
}

TEST(SelectTest, SplitRunCopiesEachPointAndItsSlotAndNothingPast) {
  // Runs of every length around the vectors' widths (16 on AVX-512, 8, 4): whole vectors, the
  // narrower ones, then single points. Oracle: the interleaved input itself; a sentinel past
  // the run's end must stay.
  test::for_each_simd_target([&] {
    std::mt19937 rng(31);  // seed 31
    std::uniform_real_distribution<float> u(-2.0f, 2.0f);
    for (const std::size_t n : {0, 1, 3, 4, 7, 8, 9, 15, 16, 17, 23, 24, 25, 31, 32, 33, 47, 100}) {
      std::vector<float> xyz(3 * n);
      for (float& v : xyz) v = u(rng);
      const float sentinel = -99.0f;
      const std::uint32_t first = 4000000000u - 40u;  // the slots near the top of the range
      std::vector<float> x(n + 1, sentinel), y(n + 1, sentinel), z(n + 1, sentinel);
      std::vector<std::uint32_t> slot(n + 1, 7);
      split_run(xyz.data(), n, first, x.data(), y.data(), z.data(), slot.data());
      for (std::size_t k = 0; k < n; ++k) {
        ASSERT_EQ(x[k], xyz[3 * k]) << n << " " << k;
        ASSERT_EQ(y[k], xyz[3 * k + 1]) << n << " " << k;
        ASSERT_EQ(z[k], xyz[3 * k + 2]) << n << " " << k;
        ASSERT_EQ(slot[k], first + k) << n << " " << k;
      }
      EXPECT_EQ(x[n], sentinel);
      EXPECT_EQ(y[n], sentinel);
      EXPECT_EQ(z[n], sentinel);
      EXPECT_EQ(slot[n], 7u);
    }
  });
}

TEST(SelectTest, LargestFloatBoundDecidesTheDoubleTestExactly) {
  // For every float v near the bound, ratio x v <= l in double holds exactly when v <= bound.
  std::mt19937 rng(29);  // seed 29
  std::uniform_real_distribution<double> lv(0.0, 10.0);
  const float inf = std::numeric_limits<float>::infinity();
  for (double ratio : {0.1, 0.25, 1.0 / 3.0, 0.5, 1.0, 7.0}) {
    for (int t = 0; t < 200; ++t) {
      const double l = t == 0 ? 0.0 : lv(rng);
      float bound = -1;
      ASSERT_TRUE(largest_float_scaled_at_or_below(ratio, l, bound));
      float v = bound;
      for (int s = 0; s < 4; ++s) v = std::nextafter(v, -inf);
      for (int s = 0; s < 9; ++s, v = std::nextafter(v, inf))
        EXPECT_EQ(ratio * static_cast<double>(v) <= l, v <= bound) << ratio << " " << l;
    }
  }
  float bound = 5;
  EXPECT_FALSE(largest_float_scaled_at_or_below(0.0, 1.0, bound));
  EXPECT_FALSE(largest_float_scaled_at_or_below(0.5, -1.0, bound));
  EXPECT_FALSE(largest_float_scaled_at_or_below(0.5, std::nan(""), bound));
  EXPECT_FALSE(largest_float_scaled_at_or_below(0.5, 1e300, bound));
  EXPECT_EQ(bound, 5);
}

}  // namespace
}  // namespace scanclean::detail

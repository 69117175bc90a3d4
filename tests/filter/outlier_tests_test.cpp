// The outlier tests after the projection (filter/src/outlier_tests.h) against brute-force
// oracles over all pairs: the density test, the likelihood-ratio test (the lower quartile by
// sorting) and the small-component test (union-find over all pairs), and the support test.

#include "../../filter/src/outlier_tests.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <numeric>
#include <random>

#include "../../filter/src/neighbor_index.h"
#include "../../filter/src/parallel.h"
#include "support/synthetic.h"

namespace scanclean::detail {
namespace {

// Representatives of their own (one member each, seed i = point i): a dense patch, a sparse
// fringe, a few isolated points and a small far clump, with random likelihoods.
struct Scene {
  std::vector<Eigen::Vector3d> x;
  Projected pr;
  Clusters cl;
  PointSet d;
  std::vector<std::uint32_t> input_index;
};

Scene make_scene(std::uint32_t seed, double h) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::uniform_real_distribution<float> l(0.5f, 1.5f);
  Scene s;
  auto add = [&](const Eigen::Vector3d& p, float L) {
    const auto i = static_cast<std::uint32_t>(s.x.size());
    s.x.push_back(p);
    s.pr.L.push_back(L);
    s.pr.iterations.push_back(2);
    s.pr.state.push_back(ProjectionState::kConverged);
    s.pr.normal.push_back(Eigen::Vector3f(0, 0, 1));
    s.cl.seed.push_back(i);
    s.cl.count.push_back(1 + i % 3);
    s.cl.position.push_back(p);
    s.cl.rep_of.push_back(i);
    s.input_index.push_back(i);
  };
  // Each point's draws last to first (its weight, then z, y, x): the order gcc took them in as
  // one argument list (test::draw_point).
  for (int k = 0; k < 900; ++k) {
    const float w = l(rng);
    const double z = 0.01 * u(rng), y = u(rng), x = u(rng);
    add(Eigen::Vector3d(x, y, z) * 5 * h, w);
  }
  for (int k = 0; k < 60; ++k) {
    const float w = l(rng);
    const double y = u(rng), x = 6 + u(rng);
    add(Eigen::Vector3d(x, y, 0) * 5 * h, w);
  }
  for (int k = 0; k < 20; ++k) {
    const float w = 0.05f * l(rng);
    const double y = u(rng), x = u(rng);
    add(Eigen::Vector3d(x, y, 0.01) * 5 * h, w);
  }
  for (int k = 0; k < 5; ++k) {
    const float w = l(rng);
    add(Eigen::Vector3d(20 + 0.1 * u(rng), 0, 0) * 5 * h, w);
  }
  s.d.h = h;
  s.d.p = s.x;
  return s;
}

RepresentativeTestInput input_of(const Scene& s, double h) {
  RepresentativeTestInput in;
  in.clusters = &s.cl;
  in.x = &s.x;
  in.projected = &s.pr;
  in.points = &s.d;
  in.input_positions = &s.x;  // no move: the displacement test is off here
  in.input_index = &s.input_index;
  in.cell = h;
  in.stride = 1;
  in.points_in = s.x.size();
  return in;
}

std::vector<std::vector<std::size_t>> neighbours(const Scene& s, double h) {
  const std::size_t n = s.x.size();
  std::vector<std::vector<std::size_t>> nb(n);
  for (std::size_t a = 0; a < n; ++a)
    for (std::size_t b = 0; b < n; ++b)
      if ((s.x[a].cast<float>() - s.x[b].cast<float>()).squaredNorm() <
          static_cast<float>(h) * static_cast<float>(h))
        nb[a].push_back(b);
  return nb;
}

FilterOptions only(double tau, double ratio, bool components) {
  FilterOptions o;
  o.tau = tau;
  o.likelihood_ratio = ratio;
  o.displacement_sigma = 0;
  o.remove_small_components = components;
  return o;
}

TEST(OutlierTestsTest, DensityTestMatchesBruteForce) {
  const double h = 0.01;
  const Scene s = make_scene(3, h);
  const auto nb = neighbours(s, h);
  std::vector<double> rho(s.x.size(), 0);
  for (std::size_t a = 0; a < nb.size(); ++a)
    for (std::size_t b : nb[a]) rho[a] += s.cl.count[b];
  const double limit = 0.3 * median_of(rho);
  const std::vector<Removal> got = test_representatives(input_of(s, h), only(0.3, 0, false));
  std::size_t removed = 0;
  for (std::size_t a = 0; a < rho.size(); ++a) {
    EXPECT_EQ(got[a] == Removal::kLowDensity, rho[a] < limit) << a;
    removed += got[a] != Removal::kKept;
  }
  EXPECT_GT(removed, 0u);
}

TEST(OutlierTestsTest, LikelihoodRatioTestMatchesTheLowerQuartile) {
  const double h = 0.01;
  const Scene s = make_scene(4, h);
  const auto nb = neighbours(s, h);
  const std::vector<Removal> got = test_representatives(input_of(s, h), only(0, 0.25, false));
  std::size_t removed = 0;
  for (std::size_t a = 0; a < nb.size(); ++a) {
    std::vector<float> l;
    for (std::size_t b : nb[a]) l.push_back(s.pr.L[b]);
    std::sort(l.begin(), l.end());
    const float q1 = l[l.size() / 4];
    EXPECT_EQ(got[a] == Removal::kLowLikelihood, s.pr.L[a] < 0.25 * q1) << a;
    removed += got[a] != Removal::kKept;
  }
  EXPECT_GE(removed, 15u);  // the 20 low-likelihood points among the dense patch
}

TEST(OutlierTestsTest, SmallComponentsMatchUnionFindOverAllPairs) {
  const double h = 0.01;
  const Scene s = make_scene(5, h);
  const auto nb = neighbours(s, h);
  const std::size_t n = s.x.size();
  std::vector<std::size_t> comp(n);
  std::iota(comp.begin(), comp.end(), 0);
  for (bool changed = true; changed;) {  // label propagation to the smallest index
    changed = false;
    for (std::size_t a = 0; a < n; ++a)
      for (std::size_t b : nb[a])
        if (comp[b] < comp[a]) {
          comp[a] = comp[b];
          changed = true;
        }
  }
  std::vector<std::uint64_t> size(n, 0);
  for (std::size_t a = 0; a < n; ++a) size[comp[a]] += s.cl.count[a];
  FilterOptions o = only(0, 0, true);
  o.min_component_size = 30;
  const std::vector<Removal> got = test_representatives(input_of(s, h), o);
  std::size_t removed = 0;
  for (std::size_t a = 0; a < n; ++a) {
    EXPECT_EQ(got[a] == Removal::kSmallComponent, size[comp[a]] < 30) << a;
    removed += got[a] != Removal::kKept;
  }
  EXPECT_GE(removed, 5u);  // at least the far clump
}

// All three tests at once with a kernel stride and a scale per point, some past the grid's cell
// (h_i up to 1.7 h, the cell h: those take the index's own query), against the rules written
// out over all pairs in the representatives' grid order: the sums run over every stride-th
// slot; the displacement test's statistics come from every 8th slot (the anchors), and a point
// whose move lies within half the threshold of the median of one of the four anchors nearest in
// that order, within its h, is kept without statistics of its own.
TEST(OutlierTestsTest, AllTestsMatchTheirRulesWithAStrideAndAScalePerPoint) {
  const double h = 0.01;
  for (std::size_t stride : {1u, 2u, 3u}) {
    Scene s = make_scene(11 + static_cast<std::uint32_t>(stride), h);
    const std::size_t n = s.x.size();
    std::mt19937 rng(20 + static_cast<std::uint32_t>(stride));
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    std::normal_distribution<double> g(0.0, 0.001);
    s.d.hi.resize(n);
    std::vector<Eigen::Vector3d> start(n);
    for (std::size_t i = 0; i < n; ++i) {
      s.d.hi[i] = static_cast<float>(h) * (i % 20 == 0 ? 1.7f : 0.6f + 0.4f * u(rng));
      const double move = i % 37 == 0 ? 0.02 : g(rng);  // a few points moved far
      start[i] = s.x[i] - Eigen::Vector3d(0, 0, move);
    }
    RepresentativeTestInput in = input_of(s, h);
    in.input_positions = &start;
    in.stride = stride;
    FilterOptions o = only(0.3, 0.25, false);
    o.displacement_sigma = 4;
    const std::vector<Removal> got = test_representatives(in, o);

    // The oracle, in the slots of the same grid.
    std::vector<Eigen::Vector3f> pf(n);
    for (std::size_t i = 0; i < n; ++i) pf[i] = s.x[i].cast<float>();
    const NeighborIndex ridx(pf, h * 1.001);
    const std::vector<std::uint32_t>& ord = ridx.order();
    std::vector<float> hs(n), moved(n), lik(n);
    std::vector<double> cnt(n);
    for (std::size_t t = 0; t < n; ++t) {
      const std::uint32_t i = ord[t];
      hs[t] = s.d.hi[i];
      moved[t] = static_cast<float>((s.x[i] - start[i]).dot(Eigen::Vector3d(0, 0, 1)));
      lik[t] = s.pr.L[i];
      cnt[t] = s.cl.count[i];
    }
    auto around = [&](std::size_t t) {
      std::vector<std::size_t> a;
      for (std::size_t q = 0; q < n; q += stride) {
        const Eigen::Vector3f d = ridx.slot_point(q) - ridx.slot_point(t);
        if ((d.x() * d.x() + d.y() * d.y()) + d.z() * d.z() < hs[t] * hs[t]) a.push_back(q);
      }
      return a;
    };
    struct Stats {
      float median = 0, scale = 0;
    };
    auto stats = [&](std::size_t t) {
      std::vector<float> v;
      for (std::size_t q : around(t)) v.push_back(moved[q]);
      Stats m;
      if (v.size() < 8) return m;
      std::sort(v.begin(), v.end());
      m.median = v[v.size() / 2];
      for (float& e : v) e = std::abs(e - m.median);
      std::sort(v.begin(), v.end());
      m.scale = std::max(1.4826f * v[v.size() / 2], 0.02f * hs[t]);
      return m;
    };
    auto displaced_by = [&](std::size_t t, const Stats& m) {
      return m.scale > 0 && static_cast<double>(std::abs(moved[t] - m.median)) >
                                4.0 * static_cast<double>(m.scale);
    };
    std::vector<Stats> anchor((n + 7) / 8);
    for (std::size_t a = 0; a < anchor.size(); ++a) anchor[a] = stats(8 * a);
    std::vector<double> rho(n);
    std::vector<bool> low_l(n), displaced(n);
    for (std::size_t t = 0; t < n; ++t) {
      std::size_t at_or_below = 0;
      const std::vector<std::size_t> a = around(t);
      for (std::size_t q : a) {
        rho[t] += cnt[q] * static_cast<double>(stride);
        at_or_below += 0.25 * static_cast<double>(lik[q]) <= static_cast<double>(lik[t]) ? 1 : 0;
      }
      low_l[t] = !a.empty() && at_or_below <= a.size() / 4;
      if (t % 8 == 0) {
        displaced[t] = displaced_by(t, anchor[t / 8]);
        continue;
      }
      bool screened = false;
      for (std::size_t k = t / 8 > 0 ? t / 8 - 1 : 0; k <= t / 8 + 2 && k < anchor.size(); ++k) {
        const float d2 = (ridx.slot_point(t) - ridx.slot_point(8 * k)).squaredNorm();
        screened = screened || (anchor[k].scale > 0 && d2 <= hs[t] * hs[t] &&
                                static_cast<double>(std::abs(moved[t] - anchor[k].median)) <=
                                    0.5 * 4.0 * static_cast<double>(anchor[k].scale));
      }
      displaced[t] = !screened && displaced_by(t, stats(t));
    }
    const double limit = 0.3 * median_of(rho);
    std::size_t counts[4] = {0, 0, 0, 0};
    for (std::size_t t = 0; t < n; ++t) {
      const Removal want = rho[t] < limit ? Removal::kLowDensity
                           : low_l[t]     ? Removal::kLowLikelihood
                           : displaced[t] ? Removal::kDisplaced
                                          : Removal::kKept;
      EXPECT_EQ(got[ord[t]], want) << "stride " << stride << ", slot " << t;
      ++counts[static_cast<int>(want)];
    }
    // Every test removed something, and most points stay.
    EXPECT_GT(counts[1], 0u) << stride;
    EXPECT_GT(counts[2], 0u) << stride;
    EXPECT_GT(counts[3], 0u) << stride;
    EXPECT_GT(counts[0], n * 3 / 4) << stride;
  }
}

TEST(OutlierTestsTest, SparseSupportUsesTheMedianOverKernels) {
  const std::vector<float> support = {10, -1, 2, 9, 11, 0.5f, -1, 12};
  // Median over the six kernels (lower median: 9), limit 0.3 x 9 = 2.7.
  const std::vector<std::uint8_t> s = sparse_support(support, 0.3);
  EXPECT_EQ(s, (std::vector<std::uint8_t>{0, 0, 1, 0, 0, 1, 0, 0}));
  EXPECT_EQ(sparse_support(support, 0), std::vector<std::uint8_t>(support.size(), 0));
}

TEST(OutlierTestsTest, SparseSupportCountsAKernelAsOftenAsItsStride) {
  const std::vector<float> support = {10, -1, 2, 9, 11, 4.8f, -1, 12};
  // Unweighted: median 9, limit 0.5 x 9 = 4.5, and 4.8 passes.
  EXPECT_EQ(sparse_support(support, 0.5), (std::vector<std::uint8_t>{0, 0, 1, 0, 0, 0, 0, 0}));
  // The first kernel stands for 4 points: 10 10 10 10 2 9 11 4.8 12, median 10, limit 5.
  const std::vector<std::uint8_t> strides = {4, 1, 1, 1, 1, 1, 1, 1};
  EXPECT_EQ(sparse_support(support, 0.5, &strides),
            (std::vector<std::uint8_t>{0, 0, 1, 0, 0, 1, 0, 0}));
}

}  // namespace
}  // namespace scanclean::detail

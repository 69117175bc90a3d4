// The clustering phase (filter/src/clustering.h) against a brute-force oracle: the same greedy
// rule over all representatives, without the grid.

#include "../../filter/src/clustering.h"

#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <random>

#include "../../filter/src/parallel.h"
#include "support/synthetic.h"

namespace scanclean::detail {
namespace {

struct Case {
  std::vector<Eigen::Vector3d> x;
  Projected pr;
};

// Points scattered in clumps (so that many merge), with random likelihoods (including ties and
// zeros), states and normals.
Case random_case(int n, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g(0.0, 1.0);
  std::uniform_int_distribution<int> pick(0, 19);
  Case c;
  std::vector<Eigen::Vector3d> centres(n / 6 + 1);
  for (auto& p : centres) p = test::draw_point(rng, g, g, g) * 0.01;
  for (int i = 0; i < n; ++i) {
    c.x.push_back(centres[static_cast<std::size_t>(i) % centres.size()] +
                  test::draw_point(rng, g, g, g) * 0.0004);
    const int k = pick(rng);
    c.pr.L.push_back(k == 0 ? 0.0f : static_cast<float>(k % 7));  // many ties
    c.pr.iterations.push_back(3);
    ProjectionState s = ProjectionState::kConverged;
    if (k == 1) s = ProjectionState::kNotConverged;
    if (k == 2) s = ProjectionState::kUnsupported;
    if (k == 3) s = ProjectionState::kOffSurface;
    c.pr.state.push_back(s);
    c.pr.normal.push_back(k % 2 ? Eigen::Vector3f(0, 0, 1) : Eigen::Vector3f(0, 0.6f, -0.8f));
  }
  return c;
}

Clusters brute_force(const Case& c, double eps, bool oriented) {
  const std::size_t n = c.x.size();
  Clusters cl;
  cl.rep_of.assign(n, kNone);
  std::vector<std::uint32_t> order;
  for (std::uint32_t i = 0; i < n; ++i)
    if (projected(c.pr.state[i])) order.push_back(i);
  std::stable_sort(order.begin(), order.end(),
                   [&](std::uint32_t a, std::uint32_t b) { return c.pr.L[a] > c.pr.L[b]; });
  std::vector<double> lsum;
  std::vector<bool> accepts;
  for (std::uint32_t i : order) {
    const bool can_join = c.pr.state[i] != ProjectionState::kNotConverged;
    std::uint32_t best = kNone;
    double best_d2 = eps * eps;
    for (std::uint32_t r = 0; can_join && r < cl.seed.size(); ++r) {
      if (!accepts[r]) continue;
      const std::uint32_t s = cl.seed[r];
      const double d2 = (c.x[s] - c.x[i]).squaredNorm();
      if (!(d2 < eps * eps)) continue;
      if (oriented && !(c.pr.normal[s].dot(c.pr.normal[i]) > 0)) continue;
      if (best == kNone || d2 < best_d2) {  // r ascends: ties keep the earlier one
        best = r;
        best_d2 = d2;
      }
    }
    const double li = std::max(0.0, static_cast<double>(c.pr.L[i]));
    if (best != kNone) {
      cl.rep_of[i] = best;
      cl.count[best] += 1;
      cl.position[best] += li * c.x[i];
      lsum[best] += li;
      continue;
    }
    cl.rep_of[i] = static_cast<std::uint32_t>(cl.seed.size());
    cl.seed.push_back(i);
    cl.count.push_back(1);
    cl.position.push_back(li * c.x[i]);
    lsum.push_back(li);
    accepts.push_back(can_join);
  }
  for (std::size_t r = 0; r < cl.seed.size(); ++r)
    cl.position[r] = lsum[r] > 0 ? Eigen::Vector3d(cl.position[r] / lsum[r]) : c.x[cl.seed[r]];
  return cl;
}

TEST(ClusteringTest, MatchesTheBruteForceGreedyRule) {
  for (int trial = 0; trial < 12; ++trial) {
    const Case c = random_case(300 + 50 * trial, 40 + trial);
    for (bool oriented : {false, true}) {
      const double eps = 0.0003 * (1 + trial % 4);
      const Clusters got = cluster_points(c.x, c.pr, eps, oriented);
      const Clusters want = brute_force(c, eps, oriented);
      ASSERT_EQ(got.seed, want.seed) << "trial " << trial;
      EXPECT_EQ(got.count, want.count);
      EXPECT_EQ(got.rep_of, want.rep_of);
      for (std::size_t r = 0; r < want.seed.size(); ++r)
        EXPECT_LT((got.position[r] - want.position[r]).norm(), 1e-15) << r;
    }
  }
}

// Points on a unit sphere about as far apart as eps: the grid spans hundreds of cells per axis,
// the candidates many chunks of the parallel passes, so that each pass's cursors start in the
// middle of the cell order and skip whole rows and planes of cells.
TEST(ClusteringTest, MatchesTheBruteForceOnASurfaceSpanningManyCells) {
  Case c = random_case(6000, 77);
  std::mt19937 rng(78);
  std::normal_distribution<double> g(0.0, 1.0);
  for (auto& p : c.x) {
    const Eigen::Vector3d d = test::draw_point(rng, g, g, g);
    p = d.normalized();
  }
  const double eps = 0.04;  // about 1.4 x the mean spacing (0.046 for 6,000 points)
  for (bool oriented : {false, true})
    for (const int threads : {1, 2}) {  // the pairs found by each thread, laid out by rank
      Clusters got;
      tbb::task_arena arena(threads);
      arena.execute([&] { got = cluster_points(c.x, c.pr, eps, oriented); });
      const Clusters want = brute_force(c, eps, oriented);
      ASSERT_EQ(got.seed, want.seed) << threads << " threads";
      EXPECT_EQ(got.count, want.count);
      EXPECT_EQ(got.rep_of, want.rep_of);
      EXPECT_LT(got.seed.size(), 5000u);  // merged
      for (std::size_t r = 0; r < want.seed.size(); ++r)
        EXPECT_LT((got.position[r] - want.position[r]).norm(), 1e-15) << r;
    }
}

TEST(ClusteringTest, MembersAccountForEveryProjectedPoint) {
  const Case c = random_case(500, 9);
  const Clusters cl = cluster_points(c.x, c.pr, 0.0008, false);
  std::size_t members = 0, projected_points = 0;
  for (std::uint32_t k : cl.count) members += k;
  for (ProjectionState s : c.pr.state) projected_points += projected(s) ? 1 : 0;
  EXPECT_EQ(members, projected_points);
  EXPECT_LT(cl.seed.size(), projected_points);  // clumps did merge
}

TEST(ClusteringTest, NoMergingDistanceKeepsEveryProjectedPoint) {
  const Case c = random_case(200, 10);
  const Clusters cl = cluster_points(c.x, c.pr, 0.0, false);
  for (std::size_t i = 0; i < c.x.size(); ++i)
    EXPECT_EQ(cl.rep_of[i] != kNone, projected(c.pr.state[i]));
  for (std::uint32_t k : cl.count) EXPECT_EQ(k, 1u);
}

}  // namespace
}  // namespace scanclean::detail

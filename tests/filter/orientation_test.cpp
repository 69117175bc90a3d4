// The orientation of normals for clouds without them (filter/src/orientation.h): the spanning
// forest against Prim's algorithm, and the oriented normals of spheres against their radii.

#include "../../filter/src/orientation.h"
#include "support/synthetic.h"

#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <cmath>
#include <limits>
#include <map>
#include <random>
#include <utility>

namespace scanclean::detail {
namespace {

// Prim's minimum spanning forest over an adjacency matrix (weight < 0: no edge), as its edges.
std::vector<std::pair<std::uint32_t, std::uint32_t>> prim(
    const std::vector<std::vector<double>>& w) {
  const std::size_t n = w.size();
  std::vector<std::pair<std::uint32_t, std::uint32_t>> tree;
  std::vector<bool> in(n, false);
  for (std::size_t start = 0; start < n; ++start) {
    if (in[start]) continue;
    in[start] = true;
    while (true) {
      double best = std::numeric_limits<double>::infinity();
      std::size_t ba = n, bb = n;
      for (std::size_t a = 0; a < n; ++a)
        if (in[a])
          for (std::size_t b = 0; b < n; ++b)
            if (!in[b] && w[a][b] >= 0 && w[a][b] < best) {
              best = w[a][b];
              ba = a;
              bb = b;
            }
      if (bb == n) break;
      in[bb] = true;
      tree.emplace_back(static_cast<std::uint32_t>(ba), static_cast<std::uint32_t>(bb));
    }
  }
  return tree;
}

TEST(OrientationTest, SpanningForestIsPrimsAndItsEdgesJoinAgreeingNormals) {
  // Random sparse graphs with distinct weights (so the minimum spanning forest is unique) and
  // random "opposite" flags: every edge of Prim's forest must join normals that agree once
  // turned, and the forest's weight must be Prim's.
  std::mt19937 rng(41);  // seed 41
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int trial = 0; trial < 30; ++trial) {
    const std::size_t n = 5 + static_cast<std::size_t>(trial) * 3;
    std::vector<std::vector<double>> w(n, std::vector<double>(n, -1.0));
    std::map<std::pair<std::uint32_t, std::uint32_t>, bool> opposite;
    std::vector<OrientationEdge> edges;
    for (std::uint32_t a = 0; a < n; ++a)
      for (std::uint32_t b = a + 1; b < n; ++b) {
        if (u(rng) > 0.3) continue;  // sparse: several trees in some trials
        OrientationEdge e;
        e.a = a;
        e.b = b;
        e.weight = static_cast<float>(u(rng));
        e.opposite = u(rng) < 0.5;
        w[a][b] = w[b][a] = e.weight;
        opposite[{a, b}] = e.opposite;
        edges.push_back(e);
        if (u(rng) < 0.2) edges.push_back(e);  // duplicates are allowed
      }
    const SpanningForest f = orient_along_spanning_forest(n, edges);
    ASSERT_EQ(f.turn.size(), n);
    const auto tree = prim(w);
    double weight = 0;
    for (auto [a, b] : tree) {
      weight += w[a][b];
      const bool opp = opposite.at({std::min(a, b), std::max(a, b)});
      EXPECT_EQ((f.turn[a] ^ f.turn[b]) != 0, opp)
          << "trial " << trial << " edge " << a << "-" << b;
      EXPECT_EQ(f.tree[a], f.tree[b]);
    }
    EXPECT_NEAR(f.weight, weight, 1e-6) << "trial " << trial;
    // Each tree's smallest node keeps its normal and names the tree.
    for (std::size_t i = 0; i < n; ++i) {
      EXPECT_LE(f.tree[i], i);
      if (f.tree[i] == i) {
        EXPECT_EQ(f.turn[i], 0);
      }
    }
  }
}

// n points on the sphere of radius r about c, noise sigma along the radius (seeded).
std::vector<Eigen::Vector3f> sphere(std::size_t n, const Eigen::Vector3f& c, float r, float sigma,
                                    std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> g(0.0f, 1.0f);
  std::vector<Eigen::Vector3f> p;
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3f d = test::draw_point(rng, g, g, g).cast<float>().normalized();
    p.push_back(c + (r + sigma * g(rng)) * d);
  }
  return p;
}

TEST(OrientationTest, NormalsOfTwoSpheresFaceOutwardTheSameForAnyThreadCount) {
  // Two noisy spheres far apart: two trees, and every normal along its sphere's outward radius
  // (each tree's highest point faces up, which on a sphere is outwards).
  const Eigen::Vector3f c0(0, 0, 0), c1(5, 0, 0);
  std::vector<Eigen::Vector3f> p = sphere(6000, c0, 1.0f, 0.01f, 42);  // seed 42
  const std::vector<Eigen::Vector3f> q = sphere(3000, c1, 0.5f, 0.005f, 43);
  p.insert(p.end(), q.begin(), q.end());
  const FilterOptions o;
  OrientedPointNormals one, two;
  tbb::task_arena(1).execute([&] { one = orient_normals(p, 48, o); });
  tbb::task_arena(2).execute([&] { two = orient_normals(p, 48, o); });
  ASSERT_EQ(one.normals.size(), p.size());
  EXPECT_EQ(one.trees, 2u);
  std::size_t outward = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    const Eigen::Vector3f radial = (p[i] - (i < 6000 ? c0 : c1)).normalized();
    EXPECT_NEAR(one.normals[i].norm(), 1.0f, 1e-5f);
    outward += one.normals[i].dot(radial) > 0.9f ? 1 : 0;
    ASSERT_EQ(one.normals[i], two.normals[i]) << i;  // bit for bit
  }
  EXPECT_EQ(outward, p.size());
}

TEST(OrientationTest, OpenSheetFacesUpAndFewPointsStillGetNormals) {
  // A noisy plane z = 0: one tree whose highest point faces up, so every normal is +z.
  std::mt19937 rng(44);  // seed 44
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::normal_distribution<float> g(0.0f, 0.002f);
  std::vector<Eigen::Vector3f> p;
  for (int i = 0; i < 4000; ++i) p.push_back(test::draw_point(rng, u, u, g).cast<float>());
  const OrientedPointNormals on = orient_normals(p, 24, FilterOptions{});
  for (const Eigen::Vector3f& n : on.normals) EXPECT_GT(n.z(), 0.9f);
  // Fewer points than k + 1: every point's PCA takes them all.
  const std::vector<Eigen::Vector3f> few(p.begin(), p.begin() + 10);
  const OrientedPointNormals small = orient_normals(few, 24, FilterOptions{});
  ASSERT_EQ(small.normals.size(), few.size());
  for (const Eigen::Vector3f& n : small.normals) EXPECT_GT(n.z(), 0.9f);
}

TEST(OrientationTest, AViewpointTurnsEachNormalToFaceIt) {
  // The cap of a sphere that a scanner 5 above it sees: every normal faces the scanner, which
  // there is outwards; seen from the centre, every normal faces inwards. No graph: no trees.
  std::vector<Eigen::Vector3f> cap;
  for (const Eigen::Vector3f& p : sphere(8000, Eigen::Vector3f::Zero(), 1.0f, 0.01f, 46))
    if (p.z() > 0.4f) cap.push_back(p);  // seed 46
  const OrientedPointNormals above =
      orient_normals(cap, 48, FilterOptions{}, Eigen::Vector3f(0, 0, 5));
  const OrientedPointNormals centre =
      orient_normals(cap, 48, FilterOptions{}, Eigen::Vector3f::Zero());
  EXPECT_EQ(above.trees, 0u);
  for (std::size_t i = 0; i < cap.size(); ++i) {
    EXPECT_GT(above.normals[i].dot(cap[i].normalized()), 0.9f) << i;
    EXPECT_EQ(centre.normals[i], -above.normals[i]) << i;
  }
}

}  // namespace
}  // namespace scanclean::detail

#include "scanclean/eval/mesh_distance.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <limits>
#include <random>
#include <thread>

#include "scanclean/core/errors.h"
#include "scanclean/io/triangle_mesh_io.h"
#include "support/data_paths.h"
#include "support/synthetic.h"

namespace scanclean {
namespace {

// Independent oracle: projection onto the plane if it falls inside (barycentric test), else the
// nearest of the three edges (clamped segment projection).
double oracle_distance(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                       const Eigen::Vector3d& c) {
  auto seg = [&p](const Eigen::Vector3d& s, const Eigen::Vector3d& e) {
    const Eigen::Vector3d d = e - s;
    const double t =
        d.squaredNorm() > 0 ? std::clamp((p - s).dot(d) / d.squaredNorm(), 0.0, 1.0) : 0.0;
    return (s + t * d - p).norm();
  };
  const Eigen::Vector3d n = (b - a).cross(c - a);
  if (n.squaredNorm() > 0) {
    const Eigen::Vector3d un = n.normalized();
    const Eigen::Vector3d q = p - un.dot(p - a) * un;
    const double u = (b - q).cross(c - q).dot(un), v = (c - q).cross(a - q).dot(un),
                 w = (a - q).cross(b - q).dot(un);
    if (u >= 0 && v >= 0 && w >= 0) return (q - p).norm();
  }
  return std::min({seg(a, b), seg(b, c), seg(c, a)});
}

double brute_force(const TriangleMesh& m, const Eigen::Vector3d& p) {
  double best = std::numeric_limits<double>::infinity();
  for (const auto& t : m.triangles)
    best = std::min(best, oracle_distance(p, m.vertices[t[0]], m.vertices[t[1]], m.vertices[t[2]]));
  return best;
}

// A closed, bumpy, irregular mesh: a UV sphere with random radial noise. Seeded.
TriangleMesh bumpy_sphere(int rings, int segments, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> noise(0.8, 1.2);
  TriangleMesh m;
  m.vertices.emplace_back(0, 0, 1);
  for (int r = 1; r < rings; ++r)
    for (int s = 0; s < segments; ++s) {
      const double th = M_PI * r / rings, ph = 2 * M_PI * s / segments;
      m.vertices.push_back(noise(rng) * Eigen::Vector3d(std::sin(th) * std::cos(ph),
                                                        std::sin(th) * std::sin(ph), std::cos(th)));
    }
  m.vertices.emplace_back(0, 0, -1);
  const int south = static_cast<int>(m.vertices.size()) - 1;
  auto id = [segments](int r, int s) { return 1 + (r - 1) * segments + (s % segments); };
  for (int s = 0; s < segments; ++s) m.triangles.push_back({0, id(1, s), id(1, s + 1)});
  for (int r = 1; r + 1 < rings; ++r)
    for (int s = 0; s < segments; ++s) {
      m.triangles.push_back({id(r, s), id(r + 1, s), id(r + 1, s + 1)});
      m.triangles.push_back({id(r, s), id(r + 1, s + 1), id(r, s + 1)});
    }
  for (int s = 0; s < segments; ++s)
    m.triangles.push_back({south, id(rings - 1, s + 1), id(rings - 1, s)});
  return m;
}

TEST(MeshDistanceTest, ClosestPointOnTriangleMatchesOracleInEveryRegion) {
  std::mt19937 rng(1);  // seed 1
  std::uniform_real_distribution<double> u(-2, 2);
  for (int i = 0; i < 20000; ++i) {
    const Eigen::Vector3d a = test::draw_point(rng, u, u, u), b = test::draw_point(rng, u, u, u),
                          c = test::draw_point(rng, u, u, u), p = test::draw_point(rng, u, u, u);
    const Eigen::Vector3d q = closest_point_on_triangle(p, a, b, c);
    ASSERT_NEAR((q - p).norm(), oracle_distance(p, a, b, c), 1e-9) << i;
  }
  // Degenerate triangles: collinear and a single point.
  const Eigen::Vector3d a(0, 0, 0), b(1, 0, 0), c(2, 0, 0), p(1.5, 1, 0);
  EXPECT_NEAR((closest_point_on_triangle(p, a, b, c) - p).norm(), 1.0, 1e-12);
  EXPECT_NEAR((closest_point_on_triangle(p, a, a, a) - p).norm(), p.norm(), 1e-12);
}

TEST(MeshDistanceTest, MatchesBruteForceOnRandomPoints) {
  const TriangleMesh m = bumpy_sphere(24, 32, 2);  // seed 2
  const MeshDistance md(m);
  std::mt19937 rng(3);  // seed 3
  std::uniform_real_distribution<double> u(-1.6, 1.6);
  for (int i = 0; i < 3000; ++i) {
    const Eigen::Vector3d p = test::draw_point(rng, u, u, u);
    const MeshDistance::Hit h = md.query(p);
    ASSERT_NEAR(h.distance, brute_force(m, p), 1e-12) << i;
    EXPECT_NEAR((h.point - p).norm(), h.distance, 1e-12);
    const auto& t = m.triangles[h.triangle];
    EXPECT_NEAR(oracle_distance(p, m.vertices[t[0]], m.vertices[t[1]], m.vertices[t[2]]),
                h.distance, 1e-12);
  }
  // Points far away and exactly on vertices.
  EXPECT_NEAR(md.distance({50, 0, 0}), brute_force(m, {50, 0, 0}), 1e-12);
  EXPECT_NEAR(md.distance(m.vertices[17]), 0.0, 1e-15);
}

TEST(MeshDistanceTest, ConcurrentQueriesGiveTheSerialResults) {
  const TriangleMesh m = bumpy_sphere(16, 20, 4);  // seed 4
  const MeshDistance md(m);
  std::mt19937 rng(5);  // seed 5
  std::uniform_real_distribution<double> u(-1.5, 1.5);
  std::vector<Eigen::Vector3d> pts(4000);
  for (auto& p : pts) p = {u(rng), u(rng), u(rng)};
  std::vector<double> serial(pts.size()), parallel(pts.size());
  for (std::size_t i = 0; i < pts.size(); ++i) serial[i] = md.distance(pts[i]);
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([&, t] {
      for (std::size_t i = static_cast<std::size_t>(t); i < pts.size(); i += 4)
        parallel[i] = md.distance(pts[i]);
    });
  for (auto& t : threads) t.join();
  EXPECT_EQ(serial, parallel);
}

TEST(MeshDistanceTest, RejectsEmptyMeshAndBadIndices) {
  EXPECT_THROW(MeshDistance(TriangleMesh{}), InputError);
  TriangleMesh m;
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  m.triangles = {{0, 1, 3}};
  EXPECT_THROW(MeshDistance{m}, InputError);
}

TEST(MeshDistanceTest, BunnyQueriesMatchBruteForce) {
  // recordings/bunny/bun_zipper.ply is part of the repository (35,947 vertices, 69,451 faces).
  // The BVH's speed is the benchmark's to measure (scanclean_bench --suite real), not a test's:
  // a wall-clock limit fails on a loaded machine.
  const TriangleMesh m = read_triangle_mesh(test::recordings_dir() / "bunny/bun_zipper.ply");
  ASSERT_EQ(m.triangles.size(), 69451u);
  const MeshDistance md(m);
  std::mt19937 rng(6);  // seed 6
  std::normal_distribution<double> noise(0.0, 0.002);
  std::uniform_int_distribution<std::size_t> pick(0, m.vertices.size() - 1);
  for (int i = 0; i < 200; ++i) {
    const Eigen::Vector3d n = test::draw_point(rng, noise, noise, noise);
    const Eigen::Vector3d p = m.vertices[pick(rng)] + n;
    ASSERT_NEAR(md.distance(p), brute_force(m, p), 1e-12) << "query " << i;
  }
}

}  // namespace
}  // namespace scanclean

#include "scanclean/mesh/surface_reconstruction.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <random>

#include "scanclean/core/errors.h"
#include "support/synthetic.h"

namespace scanclean {
namespace {

double max_edge_length(const TriangleMesh& m) {
  double longest = 0;
  for (const auto& t : m.triangles)
    for (int k = 0; k < 3; ++k)
      longest = std::max(longest, (m.vertices[static_cast<std::size_t>(t[k])] -
                                   m.vertices[static_cast<std::size_t>(t[(k + 1) % 3])])
                                      .norm());
  return longest;
}

TEST(SurfaceReconstructionTest, AdvancingFrontKeepsThePointsAsVerticesAndClosesASphere) {
  const PointCloud sphere = test::noisy_sphere(3000, 1.0, 0.0, 7);
  const MeshResult r = reconstruct_surface(sphere, {});
  ASSERT_EQ(r.mesh.vertices.size(), sphere.size());
  for (std::size_t i = 0; i < sphere.size(); ++i)
    ASSERT_EQ(r.mesh.vertices[i], sphere.positions[i]) << "vertex " << i;
  const MeshTopology& t = r.topology;
  EXPECT_EQ(t.unreferenced, 0u);
  EXPECT_EQ(t.components, 1u);
  EXPECT_EQ(t.non_manifold_edges, 0u);
  EXPECT_EQ(t.boundary_edges, 0u);
  EXPECT_EQ(t.euler, 2);
  EXPECT_EQ(t.faces, 2 * sphere.size() - 4);  // a closed genus-0 triangulation of every point
  // Every vertex lies on the sphere, and so does every triangle's centroid (nearly).
  double worst = 0;
  for (const auto& tri : r.mesh.triangles) {
    const Eigen::Vector3d c = (r.mesh.vertices[static_cast<std::size_t>(tri[0])] +
                               r.mesh.vertices[static_cast<std::size_t>(tri[1])] +
                               r.mesh.vertices[static_cast<std::size_t>(tri[2])]) /
                              3.0;
    worst = std::max(worst, 1.0 - c.norm());
  }
  EXPECT_LT(worst, 0.02);
  EXPECT_GT(r.spacing, 0.01);
  EXPECT_LT(r.spacing, 0.1);
}

TEST(SurfaceReconstructionTest, AdvancingFrontLeavesAPlanePatchOpenAsOneDisk) {
  PointCloud plane = test::noisy_plane(2000, 1.0, 1e-4, 3);
  plane.normals.clear();  // afront needs none
  const MeshResult r = reconstruct_surface(plane, {});
  const MeshTopology& t = r.topology;
  EXPECT_EQ(r.mesh.vertices.size(), plane.size());
  EXPECT_EQ(t.components, 1u);
  EXPECT_EQ(t.boundary_loops, 1u);
  EXPECT_EQ(t.non_manifold_edges, 0u);
  EXPECT_EQ(t.euler, 1);
  EXPECT_GE(t.vertices, plane.size() * 99 / 100);
}

TEST(SurfaceReconstructionTest, MaxEdgeKeepsTwoPatchesApart) {
  PointCloud a = test::noisy_plane(1000, 1.0, 1e-4, 5);
  PointCloud b = test::noisy_plane(1000, 1.0, 1e-4, 6);
  for (auto& p : b.positions) p.x() += 1.3;  // a 0.3 gap, about 10 spacings
  append(a, b);
  MeshOptions o;
  o.max_edge = 0.1;
  const MeshResult r = reconstruct_surface(a, o);
  EXPECT_DOUBLE_EQ(r.max_edge, 0.1);
  EXPECT_LE(max_edge_length(r.mesh), 0.1);
  EXPECT_EQ(r.topology.components, 2u);
  // The filter's h sets the automatic limit (2 h).
  MeshOptions with_h;
  with_h.h = 0.04;
  EXPECT_DOUBLE_EQ(reconstruct_surface(a, with_h).max_edge, 0.08);
}

TEST(SurfaceReconstructionTest, PoissonMakesAWatertightSphereNearTheTrueOne) {
  const PointCloud sphere = test::noisy_sphere(4000, 1.0, 0.0, 11);
  MeshOptions o;
  o.method = MeshMethod::kPoisson;
  const MeshResult r = reconstruct_surface(sphere, o);
  const MeshTopology& t = r.topology;
  EXPECT_TRUE(t.closed());
  EXPECT_EQ(t.boundary_edges, 0u);
  EXPECT_EQ(t.non_manifold_edges, 0u);
  EXPECT_EQ(t.components, 1u);
  EXPECT_EQ(t.euler, 2);
  EXPECT_FALSE(r.normals_reoriented);  // outward normals agree
  EXPECT_GT(r.normal_agreement, 0.99);
  double sum = 0, worst = 0;
  for (const auto& v : r.mesh.vertices) {
    const double d = std::abs(v.norm() - 1.0);
    sum += d;
    worst = std::max(worst, d);
  }
  EXPECT_LT(sum / static_cast<double>(r.mesh.vertices.size()), 0.005);
  EXPECT_LT(worst, 0.03);
}

TEST(SurfaceReconstructionTest, AdvancingFrontGivesTheSameMeshInACanonicalOrder) {
  // On a clean sample CGAL's front meets no tie, and the triangles come out in one order (CGAL's
  // own follows memory addresses). On noisy input a few percent of the triangles can differ
  // between runs: CGAL breaks ties between equal candidates by address (surface_reconstruction.h).
  const PointCloud cloud = test::noisy_sphere(3000, 1.0, 0.0, 31);
  const MeshResult a = reconstruct_surface(cloud, {});
  EXPECT_TRUE(std::is_sorted(a.mesh.triangles.begin(), a.mesh.triangles.end()));
  for (const auto& t : a.mesh.triangles) ASSERT_LT(t[0], std::min(t[1], t[2]));
  for (int run = 0; run < 2; ++run)
    EXPECT_EQ(a.mesh.triangles, reconstruct_surface(cloud, {}).mesh.triangles) << "run " << run;
  // Closed pieces face outwards: positive signed volume.
  double volume = 0;
  for (const auto& t : a.mesh.triangles)
    volume += a.mesh.vertices[static_cast<std::size_t>(t[0])].dot(
        a.mesh.vertices[static_cast<std::size_t>(t[1])].cross(
            a.mesh.vertices[static_cast<std::size_t>(t[2])]));
  EXPECT_NEAR(volume / 6.0, 4.0 / 3.0 * M_PI, 0.1);
}

TEST(SurfaceReconstructionTest, PoissonIsDeterministic) {
  const PointCloud sphere = test::noisy_sphere(2000, 1.0, 0.005, 29);
  MeshOptions o;
  o.method = MeshMethod::kPoisson;
  const MeshResult a = reconstruct_surface(sphere, o);
  const MeshResult b = reconstruct_surface(sphere, o);
  ASSERT_EQ(a.mesh.vertices.size(), b.mesh.vertices.size());
  EXPECT_EQ(a.mesh.vertices, b.mesh.vertices);
  EXPECT_EQ(a.mesh.triangles, b.mesh.triangles);
}

TEST(SurfaceReconstructionTest, PoissonRepairsAFewWrongNormals) {
  // 5 of 3000 outward normals turned inward: 99.9 % of the pairs still agree, but the five are
  // enough to matter, so `auto` runs the MST, which turns exactly those five back.
  PointCloud sphere = test::noisy_sphere(3000, 1.0, 0.0, 17);
  for (std::size_t i = 100; i < 3000; i += 600) sphere.normals[i] = -sphere.normals[i];
  MeshOptions o;
  o.method = MeshMethod::kPoisson;
  const MeshResult r = reconstruct_surface(sphere, o);
  EXPECT_GT(r.normal_agreement, 0.99);
  EXPECT_LT(r.normal_agreement, 1.0);
  EXPECT_TRUE(r.normals_reoriented);
  EXPECT_EQ(r.normals_flipped, 5u);
  EXPECT_TRUE(r.topology.closed());
  EXPECT_EQ(r.topology.euler, 2);
}

TEST(SurfaceReconstructionTest, PoissonReorientsScrambledNormals) {
  PointCloud sphere = test::noisy_sphere(3000, 1.0, 0.0, 13);
  std::mt19937 rng(5);
  for (auto& n : sphere.normals)
    if (rng() & 1u) n = -n;
  MeshOptions o;
  o.method = MeshMethod::kPoisson;
  const MeshResult r = reconstruct_surface(sphere, o);
  EXPECT_TRUE(r.normals_reoriented);
  EXPECT_LT(r.normal_agreement, 0.7);
  EXPECT_GT(r.normals_flipped, 1000u);
  EXPECT_TRUE(r.topology.closed());
  EXPECT_EQ(r.topology.euler, 2);
  double sum = 0;
  for (const auto& v : r.mesh.vertices) sum += std::abs(v.norm() - 1.0);
  EXPECT_LT(sum / static_cast<double>(r.mesh.vertices.size()), 0.005);
}

TEST(SurfaceReconstructionTest, EstimatedNormalsPointOutwardOnASphere) {
  PointCloud sphere = test::noisy_sphere(2000, 1.0, 0.0, 17);
  const auto normals = estimate_normals(sphere, 18);
  ASSERT_EQ(normals.size(), sphere.size());
  std::size_t outward = 0;
  for (std::size_t i = 0; i < sphere.size(); ++i)
    if (normals[i].cast<double>().dot(sphere.positions[i]) > 0.9) ++outward;
  EXPECT_EQ(outward, sphere.size());
}

TEST(SurfaceReconstructionTest, OrientingNormalsFaceOneWayAndNeedMoreThanKPoints) {
  // The filter's --orient-normals normals (jet over k, MST over k / 2) on a noisy sphere: every
  // one within 25 degrees of the outward normal (the MST turns the top point's up); and no
  // estimate from k points or fewer.
  PointCloud sphere = test::noisy_sphere(3000, 1.0, 0.01, 18);  // seed 18
  sphere.normals.clear();
  const auto normals = estimate_orienting_normals(sphere, 48);
  ASSERT_EQ(normals.size(), sphere.size());
  std::size_t outward = 0;
  for (std::size_t i = 0; i < sphere.size(); ++i)
    if (normals[i].cast<double>().dot(sphere.positions[i].normalized()) > 0.9) ++outward;
  EXPECT_EQ(outward, sphere.size());
  PointCloud few;
  few.positions.assign(sphere.positions.begin(), sphere.positions.begin() + 48);
  EXPECT_THROW(estimate_orienting_normals(few, 48), InputError);
}

TEST(SurfaceReconstructionTest, ErrorsNameWhatIsMissing) {
  PointCloud sphere = test::noisy_sphere(500, 1.0, 0.0, 19);
  MeshOptions poisson;
  poisson.method = MeshMethod::kPoisson;
  PointCloud bare = sphere;
  bare.normals.clear();
  try {
    reconstruct_surface(bare, poisson);
    FAIL() << "no error for missing normals";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("normals"), std::string::npos) << e.what();
  }
  PointCloud zero = sphere;
  zero.normals[42] = Eigen::Vector3f::Zero();
  try {
    reconstruct_surface(zero, poisson);
    FAIL() << "no error for a zero normal";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("point 42"), std::string::npos) << e.what();
  }
  PointCloud tiny;
  tiny.positions.assign(sphere.positions.begin(), sphere.positions.begin() + 9);
  EXPECT_THROW(reconstruct_surface(tiny, {}), InputError);
  PointCloud nan = sphere;
  nan.positions[3].x() = std::nan("");
  EXPECT_THROW(reconstruct_surface(nan, {}), InputError);
  // Collinear points: no triangle, said plainly.
  PointCloud line;
  for (int i = 0; i < 50; ++i) line.positions.emplace_back(0.01 * i, 0.02 * i, 0.0);
  try {
    reconstruct_surface(line, {});
    FAIL() << "no error for collinear points";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("collinear"), std::string::npos) << e.what();
  }
}

TEST(SurfaceReconstructionTest, ExactlyCoplanarPointsAreMeshedInTheirPlane) {
  const PointCloud flat = test::noisy_plane(500, 1.0, 0.0, 2);
  const MeshResult r = reconstruct_surface(flat, {});
  EXPECT_EQ(r.topology.components, 1u);
  EXPECT_EQ(r.topology.non_manifold_edges, 0u);
  EXPECT_GE(r.topology.vertices, 495u);
  for (const auto& v : r.mesh.vertices) EXPECT_EQ(v.z(), 0.0);
}

TEST(SurfaceReconstructionTest, BadOptionsAreRejectedBeforeWork) {
  const PointCloud sphere = test::noisy_sphere(200, 1.0, 0.0, 23);
  auto bad = [&](auto change) {
    MeshOptions o;
    change(o);
    EXPECT_THROW(validate(o), OptionError);
    EXPECT_THROW(reconstruct_surface(sphere, o), OptionError);
  };
  bad([](MeshOptions& o) { o.spacing = -1; });
  bad([](MeshOptions& o) { o.spacing_k = 0; });
  bad([](MeshOptions& o) { o.h = std::nan(""); });
  bad([](MeshOptions& o) { o.radius_ratio_bound = 0; });
  bad([](MeshOptions& o) { o.beta = 2.0; });
  bad([](MeshOptions& o) { o.poisson_angle = 40; });
  bad([](MeshOptions& o) { o.poisson_radius = 0; });
  bad([](MeshOptions& o) { o.poisson_distance = -0.1; });
  bad([](MeshOptions& o) { o.orient_k = 2; });
  EXPECT_NO_THROW(validate(MeshOptions{}));
  EXPECT_THROW(parse_mesh_method("marching"), OptionError);
  EXPECT_EQ(parse_mesh_method("poisson"), MeshMethod::kPoisson);
}

}  // namespace
}  // namespace scanclean

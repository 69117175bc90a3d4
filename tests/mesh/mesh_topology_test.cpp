#include "scanclean/mesh/mesh_topology.h"

#include <gtest/gtest.h>

namespace scanclean {
namespace {

TriangleMesh tetrahedron() {
  TriangleMesh m;
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  m.triangles = {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {0, 3, 2}};
  return m;
}

TEST(MeshTopologyTest, TetrahedronIsClosedWithEulerTwo) {
  const MeshTopology t = mesh_topology(tetrahedron());
  EXPECT_EQ(t.vertices, 4u);
  EXPECT_EQ(t.faces, 4u);
  EXPECT_EQ(t.edges, 6u);
  EXPECT_EQ(t.boundary_edges, 0u);
  EXPECT_EQ(t.boundary_loops, 0u);
  EXPECT_EQ(t.non_manifold_edges, 0u);
  EXPECT_EQ(t.components, 1u);
  EXPECT_EQ(t.euler, 2);
  EXPECT_TRUE(t.closed());
}

TEST(MeshTopologyTest, OpenTetrahedronHasOneLoopAndEulerOne) {
  TriangleMesh m = tetrahedron();
  m.triangles.pop_back();
  const MeshTopology t = mesh_topology(m);
  EXPECT_EQ(t.boundary_edges, 3u);
  EXPECT_EQ(t.boundary_loops, 1u);
  EXPECT_EQ(t.euler, 1);
  EXPECT_FALSE(t.closed());
}

TEST(MeshTopologyTest, CountsComponentsLoopsNonManifoldEdgesAndUnusedVertices) {
  TriangleMesh m = tetrahedron();
  // A separate triangle far away, one unused vertex, and a fin on edge (0, 1): 3 faces there.
  m.vertices.push_back({5, 5, 5});
  m.vertices.push_back({6, 5, 5});
  m.vertices.push_back({5, 6, 5});
  m.vertices.push_back({9, 9, 9});  // unused
  m.vertices.push_back({0.5, -1, 0});
  m.triangles.push_back({4, 5, 6});
  m.triangles.push_back({0, 1, 8});
  const MeshTopology t = mesh_topology(m);
  EXPECT_EQ(t.vertices, 8u);
  EXPECT_EQ(t.unreferenced, 1u);
  EXPECT_EQ(t.faces, 6u);
  EXPECT_EQ(t.non_manifold_edges, 1u);
  EXPECT_EQ(t.components, 2u);  // the fin is joined to the tetrahedron through the shared edge
  // Loops: the far triangle's rim and the fin's two free edges with (0,1) non-manifold: the fin's
  // free edges (1,8) (8,0) meet at 0 and 1, forming one piece.
  EXPECT_EQ(t.boundary_loops, 2u);
  EXPECT_EQ(t.boundary_edges, 5u);
}

TEST(MeshTopologyTest, DegenerateTrianglesAreCountedNotJoined) {
  TriangleMesh m;
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  m.triangles = {{0, 1, 2}, {0, 0, 1}};
  const MeshTopology t = mesh_topology(m);
  EXPECT_EQ(t.degenerate, 1u);
  EXPECT_EQ(t.components, 1u);
  EXPECT_EQ(t.euler, 1);
}

}  // namespace
}  // namespace scanclean

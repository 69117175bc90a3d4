#include "scanclean/mesh/mesh_topology.h"

#include <algorithm>
#include <cstdint>
#include <numeric>
#include <utility>
#include <vector>

namespace scanclean {
namespace {

// Union-find with path halving.
struct DisjointSets {
  std::vector<std::uint32_t> parent;
  explicit DisjointSets(std::size_t n) : parent(n) {
    std::iota(parent.begin(), parent.end(), std::uint32_t{0});
  }
  std::uint32_t find(std::uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  }
  void unite(std::uint32_t a, std::uint32_t b) {
    a = find(a);
    b = find(b);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);
  }
};

}  // namespace

MeshTopology mesh_topology(const TriangleMesh& mesh) {
  MeshTopology t;
  const std::size_t nv = mesh.vertices.size();
  const std::size_t nf = mesh.triangles.size();
  t.faces = nf;
  std::vector<std::uint8_t> used(nv, 0);
  // (min vertex, max vertex, face) for every edge of every non-degenerate triangle.
  struct EdgeRef {
    std::uint32_t a, b, face;
  };
  std::vector<EdgeRef> refs;
  refs.reserve(3 * nf);
  for (std::size_t f = 0; f < nf; ++f) {
    const auto& tri = mesh.triangles[f];
    for (int k = 0; k < 3; ++k) used[static_cast<std::size_t>(tri[k])] = 1;
    if (tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2]) {
      ++t.degenerate;
      continue;
    }
    for (int k = 0; k < 3; ++k) {
      auto a = static_cast<std::uint32_t>(tri[k]), b = static_cast<std::uint32_t>(tri[(k + 1) % 3]);
      if (a > b) std::swap(a, b);
      refs.push_back({a, b, static_cast<std::uint32_t>(f)});
    }
  }
  std::sort(refs.begin(), refs.end(), [](const EdgeRef& x, const EdgeRef& y) {
    return x.a != y.a ? x.a < y.a : (x.b != y.b ? x.b < y.b : x.face < y.face);
  });
  DisjointSets faces(nf);
  DisjointSets rim(nv);  // boundary-edge graph over vertices
  std::vector<std::uint8_t> on_rim(nv, 0);
  for (std::size_t i = 0; i < refs.size();) {
    std::size_t j = i + 1;
    while (j < refs.size() && refs[j].a == refs[i].a && refs[j].b == refs[i].b) ++j;
    ++t.edges;
    const std::size_t count = j - i;
    if (count == 1) {
      ++t.boundary_edges;
      rim.unite(refs[i].a, refs[i].b);
      on_rim[refs[i].a] = on_rim[refs[i].b] = 1;
    } else if (count > 2) {
      ++t.non_manifold_edges;
    }
    for (std::size_t k = i + 1; k < j; ++k) faces.unite(refs[i].face, refs[k].face);
    i = j;
  }
  for (std::size_t v = 0; v < nv; ++v) {
    if (used[v])
      ++t.vertices;
    else
      ++t.unreferenced;
    if (on_rim[v] && rim.find(static_cast<std::uint32_t>(v)) == v) ++t.boundary_loops;
  }
  for (std::size_t f = 0; f < nf; ++f) {
    const auto& tri = mesh.triangles[f];
    const bool degenerate = tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2];
    if (!degenerate && faces.find(static_cast<std::uint32_t>(f)) == f) ++t.components;
  }
  t.euler = static_cast<long long>(t.vertices) - static_cast<long long>(t.edges) +
            static_cast<long long>(nf - t.degenerate);
  return t;
}

}  // namespace scanclean

#pragma once
//! \file mesh_topology.h
//! Counts that say whether a triangle mesh is a usable surface: boundary loops (holes and open
//! borders), connected components, non-manifold edges, Euler characteristic.

#include <cstddef>

#include "scanclean/core/triangle_mesh.h"

namespace scanclean {

struct MeshTopology {
  std::size_t vertices = 0;            //!< vertices referenced by a triangle
  std::size_t unreferenced = 0;        //!< vertices no triangle uses
  std::size_t faces = 0;               //!< triangles (degenerate ones included)
  std::size_t degenerate = 0;          //!< triangles with a repeated vertex index
  std::size_t edges = 0;               //!< distinct undirected edges
  std::size_t boundary_edges = 0;      //!< edges with one triangle
  std::size_t non_manifold_edges = 0;  //!< edges with three or more triangles
  //! Closed chains of boundary edges: a boundary edge graph's connected pieces (a hole whose rim
  //! touches itself at a vertex counts once).
  std::size_t boundary_loops = 0;
  std::size_t components = 0;  //!< triangles connected through shared edges
  long long euler = 0;         //!< V - E + F over the referenced vertices
  //! No boundary and no non-manifold edge.
  bool closed() const { return boundary_edges == 0 && non_manifold_edges == 0 && faces > 0; }
};

//! Counts of `mesh`. Indices must be valid (as TriangleMesh requires). O(F log F).
MeshTopology mesh_topology(const TriangleMesh& mesh);

}  // namespace scanclean

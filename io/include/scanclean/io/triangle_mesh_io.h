#pragma once
//! \file triangle_mesh_io.h
//! Triangle meshes from PLY files (ascii or binary), e.g. Stanford's bun_zipper.ply.

#include <filesystem>

#include "scanclean/core/triangle_mesh.h"
#include "scanclean/io/io_types.h"

namespace scanclean {

//! Reads the vertices (x y z) and the `face` element (list property vertex_indices or
//! vertex_index) of a PLY file. Polygons with more than 3 corners are split into a triangle fan;
//! faces with fewer than 3 corners are skipped with a warning. Every index is checked.
//! Non-finite vertices are an InputError (a mesh cannot drop vertices).
//! \throw InputError (malformed file, no faces, index out of range), IoError.
TriangleMesh read_triangle_mesh(const std::filesystem::path& ply, ReadReport* report = nullptr);

}  // namespace scanclean

#pragma once
//! \file mesh_io.h
//! Writing triangle meshes as PLY (vertex x y z [nx ny nz] as float or double, face list uchar
//! int vertex_indices), atomically. Readable by scanclean's read_triangle_mesh, MeshLab,
//! CloudCompare, Blender. PLY carries no unit (metres by convention here).

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "scanclean/core/triangle_mesh.h"
#include "scanclean/io/io_types.h"

namespace scanclean {

struct MeshWriteOptions {
  PlyEncoding encoding = PlyEncoding::kBinaryLittleEndian;
  //! Header comment lines (each without "comment "; newlines are replaced by spaces).
  std::vector<std::string> comments;
  //! Drop vertices no triangle references (indices are renumbered). Default: keep them, so an
  //! interpolating mesh's vertices stay the input points in their order.
  bool drop_unreferenced = false;
};

//! Writes `mesh` to `path` (must end in .ply). Positions as float when every coordinate survives
//! the conversion within 1e-6 of the bounding-box diagonal, else as double.
//! \throw OptionError (not .ply), IoError.
void write_mesh_ply(const std::filesystem::path& path, const TriangleMesh& mesh,
                    const MeshWriteOptions& options = {});

//! Whether `path` ends in .ply (case-insensitive): the one mesh format written.
bool is_mesh_output_path(const std::filesystem::path& path);

//! The filter's kernel size h recorded in a PLY header, if any: a `comment` or `obj_info` line
//! holding `h` or `filter_h` followed by `=`, `:` or a space and a number, in metres unless
//! followed by "mm" (e.g. "h=0.0027", "h=2.7mm", "filter_h: 0.0027 m", "h 2.7 mm").
//! Returns nothing for other formats, unreadable files or no such token.
std::optional<double> recorded_kernel_size(const std::filesystem::path& cloud_file);

}  // namespace scanclean

#pragma once
//! The clean-then-mesh hand-off shared by the commands that write a cleaned cloud (`filter`,
//! `replay`, `sl decode`: `--mesh FILE`) and by `scanclean mesh` itself: option, early checks,
//! progress, the summary lines. Builds without the mesh module too: then --mesh exits 5.

#include <CLI/CLI.hpp>
#include <filesystem>
#include <memory>
#include <string>

#include "scanclean/core/point_cloud.h"
#include "scanclean/summary.h"

#if defined(SCANCLEAN_HAVE_MESH)
#include "scanclean/mesh/mesh_io.h"
#include "scanclean/mesh/surface_reconstruction.h"
#endif

namespace scanclean::app {

//! Values of the --mesh options of one command.
struct MeshHandoff {
  std::string path;               //!< --mesh FILE (.ply); empty = no mesh
  std::string method = "afront";  //!< --mesh-method
  bool wanted() const { return !path.empty(); }
};

//! Adds --mesh FILE and --mesh-method to `cmd`.
std::shared_ptr<MeshHandoff> add_mesh_option(CLI::App& cmd);

//! Before any work: --mesh must end in .ply and the mesh module must be built. No-op without
//! --mesh. \throw OptionError, UnavailableError.
void check_mesh_output(const MeshHandoff& m, const std::string& command);

//! Meshes `cloud` (the command's cleaned output, metres) with the default settings of the
//! chosen method (h: the filter's kernel size, 0 = unknown), writes the mesh and adds its lines
//! to `sum`. No-op without --mesh.
void run_mesh_handoff(const MeshHandoff& m, const PointCloud& cloud, double h, Summary& sum);

//! For commands that only have the written file: meshes `output` (or, when the command wrote
//! numbered windows OUT_0000.ply, OUT_0001.ply, ..., each of them into MESH_0000.ply, ...),
//! prints a summary titled "scanclean <command> --mesh". Returns `rc` unchanged when it is not 0
//! or there is no --mesh.
int mesh_written_output(const MeshHandoff& m, const std::filesystem::path& output,
                        const std::string& command, int rc);

#if defined(SCANCLEAN_HAVE_MESH)
//! Reconstructs (with progress bars per phase) and writes the mesh atomically.
MeshResult mesh_and_write(const PointCloud& cloud, MeshOptions options, const std::string& path,
                          const MeshWriteOptions& write);
//! The mesh's lines of a summary (method, spacing, counts, time), keys prefixed by `prefix`.
void add_mesh_summary(Summary& sum, const MeshResult& r, const std::string& prefix);
#endif

}  // namespace scanclean::app

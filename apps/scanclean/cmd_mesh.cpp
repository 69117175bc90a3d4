// scanclean mesh: a cleaned point cloud -> a triangle mesh (CGAL advancing front or Poisson).
// Needs the io and mesh modules; without them the subcommand is not built.

#if defined(SCANCLEAN_HAVE_IO) && defined(SCANCLEAN_HAVE_MESH)

#include <tbb/global_control.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include "scanclean/command.h"
#include "scanclean/core/errors.h"
#include "scanclean/io/point_cloud_io.h"
#include "scanclean/mesh/mesh_io.h"
#include "scanclean/mesh/surface_reconstruction.h"
#include "scanclean/mesh_handoff.h"
#include "scanclean/run_report.h"
#include "scanclean/summary.h"

namespace scanclean::app {
namespace {

struct MeshCommandOptions {
  std::string input;
  std::string output;
  std::string method = "afront";
  std::string orient = "auto";
  MeshOptions mesh;
  bool estimate_normals = false;
  bool drop_unreferenced = false;
  bool ascii = false;
  int threads = 0;
};

int run_mesh(MeshCommandOptions c) {
  const auto t0 = std::chrono::steady_clock::now();
  // Options and paths first: nothing is read or computed for a command line that cannot work.
  c.mesh.method = parse_mesh_method(c.method);
  c.mesh.orientation = c.orient == "keep"  ? NormalOrientation::kKeep
                       : c.orient == "mst" ? NormalOrientation::kMst
                                           : NormalOrientation::kAuto;
  validate(c.mesh);
  if (!is_mesh_output_path(c.output))
    throw OptionError("mesh: output \"" + c.output + "\": expected a .ply file name");
  const auto dir = std::filesystem::path(c.output).parent_path();
  if (!dir.empty() && !std::filesystem::is_directory(dir))
    throw IoError("mesh: output folder " + dir.string() + " does not exist");
  if (point_cloud_format(c.input).empty())
    throw OptionError("mesh: input \"" + c.input + "\": expected .ply, .pcd, .xyz or .txt");
  std::unique_ptr<tbb::global_control> limit;
  if (c.threads > 0)
    limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                  static_cast<std::size_t>(c.threads));

  note_report_input({"input", c.input});
  note_report_output({"-o", c.output});
  ReadReport report;
  PointCloud cloud = read_point_cloud(c.input, &report);
  for (const auto& w : report.warnings) std::fprintf(stderr, "scanclean: warning: %s\n", w.c_str());
  warn_dropped_invalid(c.input, report.dropped_invalid);
  std::string h_source = "unknown";
  if (c.mesh.h > 0) {
    h_source = "--h";
  } else if (const auto h = recorded_kernel_size(c.input)) {
    c.mesh.h = *h;
    h_source = "recorded in " + std::filesystem::path(c.input).filename().string();
  }
  std::string normals_source = cloud.has_normals() ? "from the file" : "none";
  if (c.estimate_normals) {
    std::fprintf(stderr, "scanclean mesh: estimating normals (jet fit, MST orientation)\n");
    cloud.normals = estimate_normals(cloud, c.mesh.orient_k);
    normals_source = "estimated (jet fit over " + std::to_string(c.mesh.orient_k) +
                     " neighbours, MST orientation)";
  }

  MeshWriteOptions w;
  w.encoding = c.ascii ? PlyEncoding::kAscii : PlyEncoding::kBinaryLittleEndian;
  w.drop_unreferenced = c.drop_unreferenced;
  w.comments.push_back(std::string("scanclean mesh method=") + to_string(c.mesh.method) + " from " +
                       std::filesystem::path(c.input).filename().string());
  const MeshResult r = mesh_and_write(cloud, c.mesh, c.output, w);

  Summary sum("scanclean mesh");
  sum.add("input", c.input);
  sum.add_count("points", cloud.size());
  sum.add("input normals", normals_source);
  sum.add("h", c.mesh.h > 0 ? std::to_string(c.mesh.h * 1e3).substr(0, 6) + " mm (" + h_source + ")"
                            : std::string("unknown (not recorded in the input)"));
  add_mesh_summary(sum, r, "");
  sum.add("output file", c.output + (c.drop_unreferenced ? " (unreferenced points dropped)" : ""));
  sum.add("total", std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 2,
          "s");
  sum.print();
  return 0;
}

const CommandRegistrar kRegistrar{{
    "mesh",
    "Reconstruct a triangle mesh from a cleaned point cloud (CGAL advancing front or Poisson)",
    35,
    [](CLI::App& cmd) {
      auto c = std::make_shared<MeshCommandOptions>();
      cmd.footer(
          "Methods: afront (default) interpolates: the mesh's vertices are the input points, "
          "open scans stay open, holes wider than --max-edge stay holes, and no normals are "
          "needed, so it suits every cloud scanclean writes (single depth frames and "
          "structured-light captures included). poisson approximates: a watertight surface "
          "from the points' oriented normals (the filter's), new vertices, holes closed; for "
          "closed objects scanned all round.\n"
          "Exit codes: 0 ok, 1 internal error, 2 bad command line or option, 3 bad input data,\n"
          "4 file I/O failure, 5 device/driver/feature unavailable, 130 interrupted.");
      cmd.add_option("input", c->input, "Cleaned point cloud (.ply .pcd .xyz .txt, metres)")
          ->required();
      cmd.add_option("-o,--output", c->output, "Output mesh (.ply, written atomically)")
          ->required();
      add_report_option(cmd);
      cmd.add_option("--method", c->method, "afront or poisson (see below)")
          ->check(CLI::IsMember({"afront", "poisson"}))
          ->capture_default_str();
      cmd.add_option("--spacing", c->mesh.spacing,
                     "Average point spacing in metres (default: CGAL compute_average_spacing)")
          ->check(positive_number());
      cmd.add_option("--spacing-k", c->mesh.spacing_k, "Neighbours of the automatic spacing")
          ->capture_default_str();
      cmd.add_option("--h", c->mesh.h,
                     "The filter's kernel size h in metres (default: read from the input's PLY "
                     "header when recorded there as h=...)")
          ->check(positive_number());
      cmd.add_option("--max-edge", c->mesh.max_edge,
                     "afront: longest triangle edge in metres; default 2 h when h is known, else "
                     "10 x spacing; -1 = no limit");
      cmd.add_option("--radius-ratio", c->mesh.radius_ratio_bound,
                     "afront: CGAL's radius_ratio_bound (larger fills more at borders)")
          ->capture_default_str();
      cmd.add_option("--beta", c->mesh.beta, "afront: CGAL's beta (radians)")
          ->capture_default_str();
      cmd.add_option("--poisson-angle", c->mesh.poisson_angle,
                     "poisson: minimum triangle angle (degrees)")
          ->capture_default_str();
      cmd.add_option("--poisson-radius", c->mesh.poisson_radius,
                     "poisson: largest triangle size, x spacing")
          ->capture_default_str();
      cmd.add_option("--poisson-distance", c->mesh.poisson_distance,
                     "poisson: surface approximation error, x spacing")
          ->capture_default_str();
      cmd.add_option("--orient", c->orient,
                     "poisson: normal orientation: auto (keep unless neighbours disagree, then "
                     "MST), keep, or mst")
          ->check(CLI::IsMember({"auto", "keep", "mst"}))
          ->capture_default_str();
      cmd.add_option("--orient-k", c->mesh.orient_k,
                     "Neighbours of the orientation check, the MST and --estimate-normals")
          ->capture_default_str();
      cmd.add_flag("--estimate-normals", c->estimate_normals,
                   "Replace the input normals by jet-fitted ones oriented by MST (for clouds "
                   "without normals; the filter's own are better)");
      cmd.add_flag("--drop-unreferenced", c->drop_unreferenced,
                   "Leave out points no triangle uses (default: kept, so the vertices are the "
                   "input points in order)");
      cmd.add_flag("--ascii", c->ascii, "Write ASCII PLY instead of binary");
      cmd.add_option("--threads", c->threads, "Worker threads, 0 = all cores")->default_val(0);
      return [c] { return run_mesh(*c); };
    },
}};

}  // namespace
}  // namespace scanclean::app

#endif  // SCANCLEAN_HAVE_IO && SCANCLEAN_HAVE_MESH

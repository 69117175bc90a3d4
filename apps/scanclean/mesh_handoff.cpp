#include "scanclean/mesh_handoff.h"

#include <cstdio>
#include <vector>

#include "scanclean/core/errors.h"

#if defined(SCANCLEAN_HAVE_MESH)
#include "scanclean/core/progress.h"
#include "scanclean/mesh/mesh_io.h"
#include "scanclean/mesh/surface_reconstruction.h"
#include "scanclean/provenance.h"
#endif
#if defined(SCANCLEAN_HAVE_IO)
#include "scanclean/io/point_cloud_io.h"
#endif

namespace scanclean::app {

std::shared_ptr<MeshHandoff> add_mesh_option(CLI::App& cmd) {
  auto m = std::make_shared<MeshHandoff>();
  cmd.add_option("--mesh", m->path,
                 "Also reconstruct a triangle mesh from the cleaned points and write it here "
                 "(.ply); the same as running scanclean mesh on the output with defaults");
  cmd.add_option("--mesh-method", m->method,
                 "With --mesh: afront (interpolating, keeps the points as vertices) or poisson "
                 "(watertight, from the filter's normals)")
      ->check(CLI::IsMember({"afront", "poisson"}))
      ->capture_default_str();
  return m;
}

void check_mesh_output(const MeshHandoff& m, const std::string& command) {
  if (!m.wanted()) return;
#if defined(SCANCLEAN_HAVE_MESH)
  if (!is_mesh_output_path(m.path))
    throw OptionError(command + ": --mesh \"" + m.path + "\": expected a .ply file name");
  const auto dir = std::filesystem::path(m.path).parent_path();
  if (!dir.empty() && !std::filesystem::is_directory(dir))
    throw IoError(command + ": --mesh \"" + m.path + "\": folder " + dir.string() +
                  " does not exist");
#else
  throw UnavailableError(command + ": --mesh: this build has no mesh module (CGAL)");
#endif
}

#if defined(SCANCLEAN_HAVE_MESH)
namespace {

// Progress bars per phase (CGAL reports none inside a phase).
std::function<void(const std::string&, double)> phase_bars(std::shared_ptr<Progress>& bar) {
  return [&bar](const std::string& phase, double fraction) {
    if (fraction <= 0) {
      bar = std::make_shared<Progress>("mesh: " + phase, 1);
    } else if (bar) {
      bar->advance(1);
      bar.reset();
    }
  };
}

std::string mm(double metres) {
  char b[48];
  std::snprintf(b, sizeof b, "%.3f mm", metres * 1e3);
  return b;
}

}  // namespace

// Shared with cmd_mesh.cpp.
void add_mesh_summary(Summary& sum, const MeshResult& r, const std::string& prefix) {
  const MeshTopology& t = r.topology;
  sum.add(prefix + "method", to_string(r.method));
  sum.add(prefix + "spacing", mm(r.spacing));
  if (r.method == MeshMethod::kAdvancingFront)
    sum.add(prefix + "max edge", r.max_edge > 0 ? mm(r.max_edge) : std::string("no limit"));
  if (r.method == MeshMethod::kPoisson) {
    char b[128];
    std::snprintf(
        b, sizeof b, "%.2f %% of neighbours agreed; %s", 100.0 * r.normal_agreement,
        r.normals_reoriented
            ? ("re-oriented by MST, " + with_thousands(r.normals_flipped) + " flipped").c_str()
            : "kept");
    sum.add(prefix + "normals", b);
  }
  sum.add(prefix + "vertices",
          with_thousands(t.vertices) + (t.unreferenced ? " (+ " + with_thousands(t.unreferenced) +
                                                             " points not in any triangle)"
                                                       : std::string()));
  sum.add_count(prefix + "faces", t.faces);
  sum.add(prefix + "boundary loops",
          with_thousands(t.boundary_loops) + " (" + with_thousands(t.boundary_edges) + " edges)");
  sum.add_count(prefix + "components", t.components);
  sum.add_count(prefix + "non-manifold edges", t.non_manifold_edges);
  sum.add(prefix + "euler characteristic",
          std::to_string(t.euler) + (t.closed() ? " (closed)" : " (open)"));
  char b[128];
  std::snprintf(b, sizeof b, "spacing %.2f, normals %.2f, reconstruction %.2f, total %.2f s",
                r.seconds_spacing, r.seconds_normals, r.seconds_reconstruction, r.seconds_total);
  sum.add(prefix + "time", b);
}

MeshResult mesh_and_write(const PointCloud& cloud, MeshOptions o, const std::string& path,
                          const MeshWriteOptions& w) {
  std::shared_ptr<Progress> bar;
  o.progress = phase_bars(bar);
  MeshResult r = reconstruct_surface(cloud, o);
  bar.reset();
  MeshWriteOptions with_provenance = w;
  with_provenance.comments.push_back(provenance_text(o.h));
  write_mesh_ply(path, r.mesh, with_provenance);
  return r;
}

void run_mesh_handoff(const MeshHandoff& m, const PointCloud& cloud, double h, Summary& sum) {
  if (!m.wanted()) return;
  MeshOptions o;
  o.method = parse_mesh_method(m.method);
  o.h = h;
  MeshWriteOptions w;
  w.comments.push_back(std::string("scanclean mesh method=") + to_string(o.method));
  const MeshResult r = mesh_and_write(cloud, o, m.path, w);
  add_mesh_summary(sum, r, "mesh ");
  sum.add("mesh file", m.path);
}

int mesh_written_output(const MeshHandoff& m, const std::filesystem::path& output,
                        const std::string& command, int rc) {
  if (rc != 0 || !m.wanted()) return rc;
  std::vector<std::pair<std::filesystem::path, std::filesystem::path>> jobs;
  if (std::filesystem::exists(output)) {
    jobs.emplace_back(output, m.path);
  } else {  // numbered windows
    const std::filesystem::path mp(m.path);
    for (int i = 0;; ++i) {
      char suffix[32];
      std::snprintf(suffix, sizeof suffix, "_%04d", i);
      const auto in =
          output.parent_path() / (output.stem().string() + suffix + output.extension().string());
      if (!std::filesystem::exists(in)) break;
      jobs.emplace_back(in,
                        mp.parent_path() / (mp.stem().string() + suffix + mp.extension().string()));
    }
  }
  if (jobs.empty())
    throw IoError(command + " --mesh: the cleaned output " + output.string() + " was not written");
  for (const auto& [in, out] : jobs) {
    const PointCloud cloud = read_point_cloud(in);
    MeshOptions o;
    o.method = parse_mesh_method(m.method);
    o.h = recorded_kernel_size(in).value_or(0.0);
    MeshWriteOptions w;
    w.comments.push_back(std::string("scanclean mesh method=") + to_string(o.method) + " from " +
                         in.filename().string());
    const MeshResult r = mesh_and_write(cloud, o, out.string(), w);
    Summary sum("scanclean " + command + " --mesh");
    sum.add("points", in.string() + " (" + with_thousands(cloud.size()) + ")");
    add_mesh_summary(sum, r, "");
    sum.add("mesh file", out.string());
    sum.print();
  }
  return rc;
}

#else

void run_mesh_handoff(const MeshHandoff& m, const PointCloud&, double, Summary&) {
  if (m.wanted()) throw UnavailableError("--mesh: this build has no mesh module (CGAL)");
}

int mesh_written_output(const MeshHandoff& m, const std::filesystem::path&, const std::string&,
                        int rc) {
  if (rc == 0 && m.wanted()) throw UnavailableError("--mesh: this build has no mesh module (CGAL)");
  return rc;
}

#endif

}  // namespace scanclean::app

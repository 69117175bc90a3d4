// scanclean filter: the robust filter (Schall, Belyaev, Seidel 2005) on point-cloud files.
// Needs the io and filter modules; without either the subcommand is not built.

#if defined(SCANCLEAN_HAVE_IO) && defined(SCANCLEAN_HAVE_FILTER)

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "scanclean/command.h"
#include "scanclean/core/atomic_file.h"
#include "scanclean/core/errors.h"
#include "scanclean/filter/robust_filter.h"
#include "scanclean/filter_options_cli.h"
#include "scanclean/io/point_cloud_io.h"
#include "scanclean/io/point_stream.h"
#include "scanclean/io/range_grid_normals.h"
#include "scanclean/mesh_handoff.h"
#include "scanclean/output_checks.h"
#include "scanclean/preview.h"
#include "scanclean/provenance.h"
#include "scanclean/run_report.h"
#include "scanclean/summary.h"
#include "scanclean/tiled_run.h"

namespace scanclean::app {
namespace {

struct FilterCommandOptions {
  std::vector<std::string> inputs;
  std::string output;
  std::string conf;
  std::string outliers;
  bool ascii = false;
  bool skip_missing = false;
  std::string xyz_columns;
  std::shared_ptr<MeshHandoff> mesh;     // --mesh FILE
  std::shared_ptr<std::string> preview;  // --preview FILE.png
  std::string memory_budget;             // --memory-budget SIZE | off (default: automatic)
  bool tiled = false;                    // --tiled: tile even when the cloud would fit
  std::string scratch;                   // --scratch DIR
  double halo = 4.0;                     // --halo FACTOR
  int orient_normals = 0;                // --orient-normals K: 0 = off
  std::vector<double> viewpoint;         // --viewpoint X,Y,Z: empty = off
};

// --viewpoint: an organized input without normals gets its grid's (range_grid_normals), facing
// the scanner at `viewpoint`; an input with normals keeps them; an unorganized one without is
// left to the filter (FilterOptions::orient_viewpoint). Returns the number of normals given.
std::size_t add_viewpoint_normals(const std::string& file, const std::vector<double>& viewpoint,
                                  PointCloud& part) {
  if (part.has_normals()) {
    std::fprintf(stderr,
                 "scanclean: %s: has normals of its own; --viewpoint leaves them as they are\n",
                 file.c_str());
    return 0;
  }
  if (part.grid.empty()) return 0;
  const Eigen::Vector3d at(viewpoint[0], viewpoint[1], viewpoint[2]);
  const RangeGridNormals n = range_grid_normals_from_viewpoint(part, at);
  if (n.with_normal == 0)
    throw InputError("filter: " + file +
                     ": its grid gives no normal (no point has filled cells two steps away on all "
                     "four sides, within the depth-jump limit); --viewpoint cannot orient it");
  if (n.facing < n.with_normal * 9 / 10)
    std::fprintf(stderr,
                 "scanclean: warning: %s: only %zu of the grid's %zu normals face the "
                 "viewpoint (%g, %g, %g) m; is it where the scanner was, in the cloud's frame?\n",
                 file.c_str(), n.facing, n.with_normal, viewpoint[0], viewpoint[1], viewpoint[2]);
  part.normals = n.normals;
  return n.with_normal;
}

void print_warnings(const std::string& file, const ReadReport& report) {
  for (const auto& w : report.warnings) std::fprintf(stderr, "scanclean: warning: %s\n", w.c_str());
  warn_dropped_invalid(file, report.dropped_invalid);
}

// The tiled run (tiled_run.h) when it applies: returns the exit code, or -1 to run in memory.
int run_filter_tiled(const FilterCommandOptions& c, const FilterOptions& o) {
  const bool off = c.memory_budget == "off";
  if (off && c.tiled) throw OptionError("filter: --tiled needs a memory budget (not off)");
  if (off) return -1;
  TiledOptions t;
  t.memory_budget = c.memory_budget.empty() ? default_memory_budget()
                                            : parse_memory_size("--memory-budget", c.memory_budget);
  t.halo_factor = c.halo;
  if (!c.scratch.empty()) t.scratch = c.scratch;
  validate(t);
  const std::string& in = c.inputs.front();
  std::unique_ptr<PointStream> stream;
  try {
    stream = PointStream::open(in);  // the header only
  } catch (const std::exception&) {  // not streamable (PointStream::streamable's rule)
  }
  if (!stream) {
    if (c.tiled)
      throw OptionError(
          "filter: --tiled needs a binary PLY or binary PCD input (streamed by "
          "byte ranges); convert it with scanclean convert");
    return -1;
  }
  const auto records = stream->size();
  if (!c.tiled && in_memory_bytes(records, stream->attributes().size()) <= t.memory_budget)
    return -1;
  if (point_cloud_format(c.output) != "ply" ||
      (!c.outliers.empty() && point_cloud_format(c.outliers) != "ply") || c.ascii)
    throw OptionError("filter: the tiled (out-of-core) run of " + with_thousands(records) +
                      " points writes binary PLY only: use a .ply output (or filter in memory: "
                      "--memory-budget off, or a larger budget)");
  if (!c.mesh->path.empty())
    throw OptionError(
        "filter: --mesh needs the whole cloud in memory; it cannot follow a tiled "
        "run (raise --memory-budget, or mesh the output afterwards)");
  if (!c.preview->empty())
    throw OptionError(
        "filter: --preview draws the whole cloud before and after; it cannot follow a tiled "
        "run (raise --memory-budget)");
  if (c.orient_normals > 0)
    throw OptionError(
        "filter: --orient-normals orients over the whole cloud; it cannot precede a tiled run "
        "(raise --memory-budget)");
  if (!c.viewpoint.empty())
    throw OptionError(
        "filter: --viewpoint reads the input's grid, which a tiled run does not keep (raise "
        "--memory-budget)");
  TiledRunRequest req;
  req.input = in;
  req.output = c.output;
  req.outliers = c.outliers;
  req.filter = o;
  req.tiled = t;
  FilterOptions bar_options;
  FilterProgress progress(bar_options);
  req.tiled.progress = bar_options.progress;
  const TiledRunResult r = run_tiled(req);
  progress.finish();
  const TiledStats& s = r.stats;
  const TiledGlobals& g = s.globals;
  Summary sum("scanclean filter (tiled, out of core)");
  sum.add("input", in);
  if (r.dropped_invalid > 0) sum.add_count("invalid dropped", r.dropped_invalid);
  sum.add_count("points in", s.points_in);
  sum.add_count("points out", s.points_out);
  sum.add_count("merged into others", s.merged);
  sum.add("outliers removed",
          with_thousands(s.outliers) + " (unsupported " + with_thousands(s.unsupported) + ")");
  if (!c.outliers.empty()) sum.add("outliers file", r.written ? c.outliers : "not written");
  sum.add("output file", r.written ? c.output : "not written (collapsed result)");
  sum.add("scale", std::string(scale_mode_name(o.scale)));
  sum.add("h", g.h * 1000.0, 3, "mm");
  if (o.scale == ScaleMode::kAuto)
    sum.add("noise sigma (estimate)", g.noise_sigma * 1000.0, 3, "mm");
  sum.add("merge eps", g.merge_eps * 1000.0, 3, "mm");
  sum.add("kernel stride", std::to_string(g.kernel_stride));
  char halo[48];
  std::snprintf(halo, sizeof halo, "%.1f mm", g.halo * 1000.0);
  sum.add("tiles", std::to_string(s.tiles) + " (halo " + halo + ", " +
                       with_thousands(s.halo_points) + " halo points, largest tile " +
                       with_thousands(s.tile_points_max) + ")");
  char phases[160];
  std::snprintf(phases, sizeof phases, "first pass %.2f, distribution %.2f, tiles %.2f s",
                s.seconds_globals, s.seconds_distribute, s.seconds_tiles);
  sum.add("time", phases);
  sum.add("total", s.seconds_total, 2, "s");
  sum.add_count("points per second", static_cast<unsigned long long>(
                                         s.seconds_total > 0 ? s.points_in / s.seconds_total : 0));
  sum.add("memory budget", static_cast<double>(t.memory_budget) / 1048576.0, 0, "MiB");
  sum.add("peak memory", static_cast<double>(s.peak_rss_bytes) / 1048576.0, 1, "MiB");
  sum.print();
  warn_dropped_invalid(in, r.dropped_invalid);
  if (!r.written) {
    std::fprintf(stderr,
                 "scanclean filter: error: the result has %llu point(s) from %llu input points, "
                 "nothing usable; nothing was written; check --h, --k and --merge-eps\n",
                 static_cast<unsigned long long>(s.points_out),
                 static_cast<unsigned long long>(s.points_in));
    return static_cast<int>(ExitCode::kEmptyResult);
  }
  warn_if_mostly_unsupported(s.unsupported, s.points_in, g.h);
  return 0;
}

int run_filter(FilterCommandOptions c, const FilterCliValues& values) {
  // Without -o, the last positional argument is the output (filter IN... OUT).
  if (c.output.empty()) {
    if (c.inputs.size() >= 2 || (c.inputs.size() == 1 && !c.conf.empty())) {
      c.output = c.inputs.back();
      c.inputs.pop_back();
    } else {
      throw OptionError(
          "filter: no output given: use -o/--output OUT (or put OUT last: filter IN... OUT)");
    }
  }
  if (c.inputs.empty() && c.conf.empty())
    throw OptionError("filter: give at least one input file or --conf FILE");
  // Every check before the first byte of input is read.
  std::vector<PathArg> inputs;
  for (const auto& in : c.inputs) inputs.push_back({"input", in});
  if (!c.conf.empty()) inputs.push_back({"--conf", c.conf});
  check_input_files("filter", inputs);
  check_output_files("filter", inputs,
                     {{"-o", c.output}, {"--outliers", c.outliers}, {"--mesh", c.mesh->path}});
  FilterOptions o = to_filter_options(values);
  validate(o);
  WriteOptions w;
  if (c.ascii) {
    w.ply_encoding = PlyEncoding::kAscii;
    w.pcd_encoding = "ascii";
  }
  XyzOptions xyz;
  if (!c.xyz_columns.empty()) xyz.columns = parse_xyz_columns(c.xyz_columns);

  check_mesh_output(*c.mesh, "filter");
  check_preview_path("filter", *c.preview);
  if (c.orient_normals != 0 && (c.orient_normals < kMinOrientK || c.orient_normals > kMaxOrientK))
    throw OptionError("--orient-normals: expected 0 (off) or an integer in [" +
                      std::to_string(kMinOrientK) + ", " + std::to_string(kMaxOrientK) + "], got " +
                      std::to_string(c.orient_normals));
  if (c.orient_normals > 0 && !o.use_sensor_normals)
    throw OptionError("filter: --orient-normals and --no-sensor-normals exclude each other");
  if (!c.viewpoint.empty()) {
    if (c.viewpoint.size() != 3 || !std::all_of(c.viewpoint.begin(), c.viewpoint.end(),
                                                [](double v) { return std::isfinite(v); }))
      throw OptionError("filter: --viewpoint: expected three finite numbers X,Y,Z (metres)");
    if (c.inputs.empty())
      throw OptionError(
          "filter: --viewpoint applies to the input files (a --conf session's scans have "
          "their own normals); give an organized input file");
    if (!o.use_sensor_normals)
      throw OptionError("filter: --viewpoint and --no-sensor-normals exclude each other");
  }

  // Out of core: one binary PLY/PCD input larger than the memory budget (or --tiled).
  if (c.conf.empty() && c.inputs.size() == 1) {
    const int tiled = run_filter_tiled(c, o);
    if (tiled >= 0) return tiled;
  }

  PointCloud cloud;
  std::size_t files = 0;
  std::size_t grid_points = 0, grid_normals = 0;  // --viewpoint: inputs' points, with a normal
  std::string unorganized;                        // --viewpoint: an input without a grid or normals
  for (const auto& in : c.inputs) {
    ReadReport report;
    PointCloud part = read_point_cloud(in, &report, xyz);
    print_warnings(in, report);
    if (!c.viewpoint.empty()) {
      const std::size_t given = add_viewpoint_normals(in, c.viewpoint, part);
      grid_normals += given;
      // The grid's normals orient the kernels' PCA normals and choose their neighbours, but do
      // not replace them: central differences over a few cells are as noisy as the depths (a
      // depth camera's range image of a sphere with 1 mm noise, `scanclean_bench --suite real`:
      // 0.193 mm RMS from the sphere with them as the kernels' normals, 0.134 mm without, 0.138
      // mm as here).
      if (given > 0) o.normals_orient_only = true;
      grid_points += part.size();
      if (part.grid.empty() && !part.has_normals()) unorganized = in;
    }
    append(cloud, part);
    ++files;
  }
  std::string scan_normals;  // the --conf session's normals, for the summary
  if (!c.conf.empty()) {
    ReadReport report;
    ConfOptions conf_options;
    conf_options.skip_missing = c.skip_missing;
    PointCloud part = read_and_merge_conf(c.conf, &report, conf_options);
    if (report_path())  // --report: the scans the session read, too
      for (const auto& scan : read_conf(c.conf).files)
        if (std::filesystem::exists(scan)) note_report_input({"--conf scan", scan});
    print_warnings(c.conf, report);
    if (part.has_normals()) {
      std::size_t with = 0;
      for (const auto& n : part.normals) with += n.isZero() ? 0 : 1;
      scan_normals = "the scans' range grids, " + with_thousands(with) + " of " +
                     with_thousands(part.size()) + " points" +
                     (o.use_sensor_normals ? "" : " (not used: --no-sensor-normals)");
    }
    append(cloud, part);
    ++files;
  }

  if (cloud.empty())
    throw InputError(
        "filter: the inputs hold no points (every file is empty or every point was "
        "invalid); nothing to filter");
  // Normals for a cloud without them, oriented by the filter itself (FilterOptions::orient_k):
  // they keep the sides of thin parts apart. Input normals are kept as they are.
  // With --viewpoint, an unorganized cloud's PCA normals are turned to face the scanner instead.
  if (!unorganized.empty() && grid_normals > 0)
    throw OptionError(
        "filter: --viewpoint with organized inputs (their grids' normals) and an "
        "unorganized one (" +
        unorganized + ", PCA normals): filter them separately");
  const bool to_viewpoint = !unorganized.empty() && !cloud.has_normals();
  const bool orienting = (c.orient_normals > 0 || to_viewpoint) && !cloud.has_normals();
  if (orienting) o.orient_k = c.orient_normals > 0 ? c.orient_normals : kSuitedOrientK;
  if (to_viewpoint) o.orient_viewpoint = {c.viewpoint[0], c.viewpoint[1], c.viewpoint[2]};
  FilterProgress progress(o);
  const FilterResult r = robust_filter(cloud, o);
  progress.finish();

  // Empty (from any input) or one point from more: nothing usable; exit 6, nothing written.
  const bool collapsed = (r.cloud.empty() && r.stats.points_in >= 1) ||
                         (r.cloud.size() == 1 && r.stats.points_in >= 2);
  if (!collapsed) {
    w.provenance = provenance_text(r.stats.h, r.stats.noise_sigma);
    AtomicCommitGroup both;  // the cleaned cloud and the outliers, or neither
    write_point_cloud(c.output, r.cloud, w);
    if (!c.outliers.empty()) write_point_cloud(c.outliers, r.outliers, w);
    both.commit();
  }

  const FilterStats& s = r.stats;
  Summary sum("scanclean filter");
  sum.add("input", std::to_string(files) + (files == 1 ? " file" : " files"));
  sum.add_count("points in", s.points_in);
  sum.add_count("points out", s.points_out);
  sum.add_count("merged into others", s.merged);
  sum.add("outliers removed",
          with_thousands(s.removed()) + " (unsupported " + with_thousands(s.unsupported) +
              ", off surface " + with_thousands(s.off_surface) + ", low density " +
              with_thousands(s.low_density) + ", low likelihood " +
              with_thousands(s.low_likelihood) + ", displaced " + with_thousands(s.displaced) +
              ", small components " + with_thousands(s.small_components) + ")");
  if (!c.outliers.empty()) sum.add("outliers file", collapsed ? "not written" : c.outliers);
  sum.add("output file", collapsed ? "not written (collapsed result)" : c.output);
  if (orienting) {
    char text[200];
    if (to_viewpoint)
      std::snprintf(text, sizeof text,
                    "estimated (PCA over %d neighbours) and turned to face the viewpoint (%.4g, "
                    "%.4g, %.4g) m in %.2f s",
                    o.orient_k, c.viewpoint[0], c.viewpoint[1], c.viewpoint[2],
                    s.seconds_orientation);
    else
      std::snprintf(text, sizeof text,
                    "estimated (PCA over %d neighbours) and oriented (spanning forest over %d) in "
                    "%.2f s",
                    o.orient_k, kOrientationGraphNeighbours, s.seconds_orientation);
    sum.add("normals", text);
  } else if (grid_normals > 0) {
    char text[200];
    std::snprintf(text, sizeof text,
                  "the range grid, facing the viewpoint (%.4g, %.4g, %.4g) m, %s of %s points",
                  c.viewpoint[0], c.viewpoint[1], c.viewpoint[2],
                  with_thousands(grid_normals).c_str(), with_thousands(grid_points).c_str());
    sum.add("normals", text);
  } else if (c.orient_normals > 0) {
    sum.add("normals", "the input's normals (--orient-normals not needed)");
  } else if (!scan_normals.empty()) {
    sum.add("normals", scan_normals);
  }
  sum.add("scale", std::string(scale_mode_name(o.scale)));
  sum.add("h", s.h * 1000.0, 3, "mm");
  if (o.scale == ScaleMode::kAdaptive || o.scale_regions > 0) {
    char range[96];
    std::snprintf(range, sizeof range, "%.3f .. %.3f mm (median shown as h)", s.h_min * 1000.0,
                  s.h_max * 1000.0);
    sum.add("h range", range);
  }
  if (o.scale == ScaleMode::kAuto) {
    sum.add("noise sigma (estimate)", s.noise_sigma * 1000.0, 3, "mm");
    if (o.scale_gamma > 0) sum.add("h before the scale test", s.h_noise * 1000.0, 3, "mm");
    if (o.scale_regions > 0 && o.crease_spread > 0)
      sum.add_count("scale test: samples beside creases", s.scale_crease_samples);
  }
  sum.add("mean spacing", s.mean_spacing * 1000.0, 3, "mm");
  sum.add("kernels", with_thousands(s.kernels) +
                         (s.kernel_stride == 1
                              ? std::string(" (at every point)")
                              : " (at one point in " + std::to_string(s.kernel_stride) + ")"));
  if (o.crease_spread > 0) sum.add_count("kernels split at creases", s.kernels_split);
  if (o.refit_spread > 0) sum.add_count("kernels refitted on their sheet", s.kernels_refitted);
  sum.add("merge eps", s.merge_eps * 1000.0, 3, "mm");
  sum.add("iterations", std::to_string(s.mean_iterations).substr(0, 4) + " mean, " +
                            std::to_string(static_cast<int>(s.p95_iterations)) + " p95");
  sum.add_count("not converged", s.not_converged);
  char phases[256];
  std::snprintf(phases, sizeof phases,
                "scale %.2f, kernels %.2f, projection %.2f, clustering %.2f, outliers %.2f s",
                s.seconds_scale, s.seconds_kernels, s.seconds_projection, s.seconds_clustering,
                s.seconds_outliers);
  sum.add("time", phases);
  sum.add("total", s.seconds_total, 2, "s");
  sum.add_count("points per second", static_cast<unsigned long long>(
                                         s.seconds_total > 0 ? s.points_in / s.seconds_total : 0));
  sum.add("threads", std::to_string(s.threads));
  sum.add("peak memory", static_cast<double>(s.peak_rss_bytes) / 1048576.0, 1, "MiB");
  note_report_filter(c.output, s);
  if (!c.preview->empty() && !collapsed) {
    PreviewOptions po;
    po.title = command_line();
    sum.add("preview", preview_summary_text(
                           *c.preview, write_preview(*c.preview, cloud, r.cloud, r.outliers, po)));
  }
  run_mesh_handoff(*c.mesh, r.cloud, s.h, sum);
  sum.print();
  if (collapsed) {
    std::fprintf(stderr,
                 "scanclean filter: error: the result has %zu point(s) from %zu input points, "
                 "nothing usable (h %.6g m, merge eps %.6g m); nothing was written; check --h, "
                 "--k and --merge-eps\n",
                 r.cloud.size(), r.stats.points_in, r.stats.h, r.stats.merge_eps);
    return static_cast<int>(ExitCode::kEmptyResult);
  }
  warn_if_mostly_unsupported(s.unsupported, s.points_in, s.h);
  return 0;
}

const CommandRegistrar kRegistrar{{
    "filter",
    "Robust filter: denoise a point cloud and remove outliers (Schall et al. 2005)",
    30,
    [](CLI::App& cmd) {
      auto c = std::make_shared<FilterCommandOptions>();
      cmd.add_option("inputs", c->inputs,
                     "Input point clouds (.ply .pcd .xyz .txt, metres); several are merged. "
                     "Without -o, the last one is the output");
      cmd.add_option("-o,--output", c->output, "Output point cloud (format by extension)");
      cmd.add_option("--conf", c->conf,
                     "Stanford .conf scan session: every scan transformed and merged (added to "
                     "the inputs); each scan's range grid gives its points normals facing the "
                     "scanner, so kernels fit only neighbours facing their way and with a "
                     "normal (scan borders, depth jumps and hole edges have none); "
                     "--no-sensor-normals ignores them");
      cmd.add_flag("--skip-missing", c->skip_missing,
                   "With --conf: merge the scans that exist, warn about missing ones (default: "
                   "a missing scan is an error)");
      cmd.add_option("--outliers", c->outliers,
                     "Write the removed input points here (attribute flags: 1 unsupported, 2 "
                     "outlier)");
      cmd.add_option("--xyz-columns", c->xyz_columns,
                     "Columns of .xyz/.txt inputs, comma-separated, e.g. x,y,z,r,g,b or "
                     "x,y,z,nx,ny,nz or x,y,z,i (names: x y z nx ny nz r g b i, '-' = skip); "
                     "default: guessed from the first line (see scanclean info)");
      cmd.add_flag("--ascii", c->ascii, "Write ASCII PLY/PCD instead of binary");
      c->mesh = add_mesh_option(cmd);
      add_report_option(cmd);
      c->preview = add_preview_option(cmd);
      cmd.add_option("--memory-budget", c->memory_budget,
                     "Peak memory to aim for, e.g. 2G or 1536M (default: 2G, or half the "
                     "machine's memory if less); a binary PLY/PCD input that needs more is "
                     "filtered out of core, by tiles (output: binary PLY); 'off' never tiles");
      cmd.add_flag("--tiled", c->tiled,
                   "Filter by tiles even when the cloud fits the memory budget");
      cmd.add_option("--scratch", c->scratch,
                     "Folder for the tiled run's scratch files (default: a private folder "
                     "beside the output; about the input's size, removed at the end)");
      cmd.add_option("--halo", c->halo,
                     "Tiled run: the halo around each tile, in units of h (default 4)");
      cmd.add_option("--orient-normals", c->orient_normals,
                     "For a cloud without normals: estimate normals over K neighbours (PCA) and "
                     "orient them consistently (minimum spanning forest over the 12 nearest, as "
                     "CGAL's mst_orient_normals) before filtering; they keep the two sides of "
                     "thin parts apart (kernels only gather neighbours facing their way). 96 "
                     "suits the benchmark's shapes and costs about 3 s and 150 MB per million "
                     "points. In [6, 200]; default 0 = off");
      cmd.add_option("--viewpoint", c->viewpoint,
                     "X,Y,Z: where the scanner was, for a cloud taken from one place, in the "
                     "input's frame (metres; 0,0,0 for a depth camera's cloud in its own frame). "
                     "An organized input without normals (PLY range_grid, PCD with HEIGHT > 1) "
                     "gets its grid's normals, an unorganized one PCA normals (over "
                     "--orient-normals K neighbours, default 96), turned to face it: they orient "
                     "the kernels' normals, so the output's normals face the scanner (as PCL's "
                     "and Open3D's viewpoint orientation), and kernels fit only neighbours facing "
                     "their way (grid borders, depth jumps and hole edges have no grid normal)")
          ->expected(3)
          ->delimiter(',');
      auto values = add_filter_options(cmd);
      return [c, values] { return run_filter(*c, *values); };
    },
}};

}  // namespace
}  // namespace scanclean::app

#endif  // SCANCLEAN_HAVE_IO && SCANCLEAN_HAVE_FILTER

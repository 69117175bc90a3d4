// scanclean info: describe point-cloud files (format, counts, fields, grid, bounds, spacing).
#if defined(SCANCLEAN_HAVE_IO)

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <nanoflann.hpp>
#include <random>
#include <string>
#include <vector>

#include "scanclean/command.h"
#include "scanclean/core/errors.h"
#include "scanclean/io/point_cloud_io.h"
#include "scanclean/run_report.h"
#include "scanclean/summary.h"

namespace scanclean::app {
namespace {

struct CloudAdaptor {
  const std::vector<Eigen::Vector3d>& pts;
  std::size_t kdtree_get_point_count() const { return pts.size(); }
  double kdtree_get_pt(std::size_t i, std::size_t d) const { return pts[i][static_cast<int>(d)]; }
  template <class Box>
  bool kdtree_get_bbox(Box&) const {
    return false;
  }
};

//! Median nearest-neighbour distance between distinct positions, over up to max_samples evenly
//! spaced ones (metres); -1 when there are fewer than 2 distinct positions. Coincident points
//! are merged first (a k-d tree over many equal points degenerates); `duplicates` receives how
//! many points repeat an earlier position.
double median_spacing(const PointCloud& cloud, std::size_t max_samples, std::size_t* duplicates) {
  std::vector<Eigen::Vector3d> distinct(cloud.positions);
  auto less = [](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    return std::lexicographical_compare(a.data(), a.data() + 3, b.data(), b.data() + 3);
  };
  std::sort(distinct.begin(), distinct.end(), less);
  distinct.erase(std::unique(distinct.begin(), distinct.end()), distinct.end());
  *duplicates = cloud.size() - distinct.size();
  if (distinct.size() < 2) return -1;
  // Back to an even spread over the cloud for the samples (sorted order would sample a slab).
  std::vector<Eigen::Vector3d> points;
  points.reserve(distinct.size());
  {
    std::vector<std::size_t> order(distinct.size());
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::mt19937_64 rng(12345);
    std::shuffle(order.begin(), order.end(), rng);
    for (auto i : order) points.push_back(distinct[i]);
  }
  using Tree =
      nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, CloudAdaptor>,
                                          CloudAdaptor, 3, std::uint32_t>;
  CloudAdaptor adaptor{points};
  Tree tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(16));
  const std::size_t samples = std::min(max_samples, points.size());
  std::vector<double> d;
  d.reserve(samples);
  for (std::size_t s = 0; s < samples; ++s) {
    const std::size_t i = s * points.size() / samples;
    std::uint32_t idx[2];
    double dist2[2];
    const auto found = tree.knnSearch(points[i].data(), 2, idx, dist2);
    if (found == 2) d.push_back(std::sqrt(dist2[1]));
  }
  if (d.empty()) return -1;
  std::nth_element(d.begin(), d.begin() + static_cast<std::ptrdiff_t>(d.size() / 2), d.end());
  return d[d.size() / 2];
}

std::string fmt(double v, int precision) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", precision, v);
  return buf;
}

void describe(const std::string& path, bool skip_missing, std::size_t max_warnings,
              const XyzOptions& xyz) {
  note_report_input({"files", path});
  ReadReport r;
  PointCloud c;
  const bool conf = std::filesystem::path(path).extension() == ".conf";
  if (conf)
    c = read_and_merge_conf(path, &r, ConfOptions{skip_missing});
  else
    c = read_point_cloud(path, &r, xyz);
  Summary s(path);
  s.add("format", r.format + (r.encoding.empty() ? "" : " (" + r.encoding + ")"));
  s.add("points", with_thousands(c.size()) + " (declared " + with_thousands(r.declared_points) +
                      ", invalid dropped " + with_thousands(r.dropped_invalid) + ")");
  if (!r.fields.empty()) {
    std::string f;
    for (const auto& x : r.fields) f += (f.empty() ? "" : " ") + x;
    s.add("fields", f);
  }
  std::string arrays = "positions";
  if (c.has_normals()) arrays += ", normals";
  if (c.has_confidences()) arrays += ", confidences";
  if (c.has_intensities()) arrays += ", intensities";
  if (c.has_colors()) arrays += ", colours";
  for (const auto& a : c.attributes) arrays += ", " + a.name;
  s.add("kept as", arrays);
  if (!c.grid.empty()) {
    std::size_t filled = 0;
    for (auto i : c.grid.index) filled += i >= 0;
    s.add("organized", std::to_string(c.grid.rows) + " rows x " + std::to_string(c.grid.cols) +
                           " cols (" + with_thousands(filled) + " of " +
                           with_thousands(c.grid.index.size()) + " cells filled)");
  } else {
    s.add("organized", "no");
  }
  if (!c.empty()) {
    const auto b = bounding_box(c);
    auto range = [&](int k) { return fmt(b.min()[k], 4) + " .. " + fmt(b.max()[k], 4); };
    s.add("bounding box", "x " + range(0) + ", y " + range(1) + ", z " + range(2) + " m");
    const Eigen::Vector3d size = b.sizes();
    s.add("size", fmt(size.x(), 4) + " x " + fmt(size.y(), 4) + " x " + fmt(size.z(), 4) + " m");
    std::size_t duplicates = 0;
    const double spacing = median_spacing(c, 10000, &duplicates);
    if (spacing >= 0)
      s.add("mean spacing",
            fmt(spacing * 1e3, 3) + " mm (median nearest-neighbour distance over " +
                with_thousands(std::min<std::size_t>(10000, c.size() - duplicates)) +
                " distinct points)");
    else if (c.size() >= 2)
      s.add("mean spacing", "none (every point at the same position)");
    if (duplicates > 0)
      s.add("coincident points", with_thousands(duplicates) + " repeat an earlier position");
  }
  s.add_count("warnings", r.warnings.size());
  s.print();
  for (std::size_t i = 0; i < r.warnings.size() && i < max_warnings; ++i)
    std::printf("    warning: %s\n", r.warnings[i].c_str());
  if (r.warnings.size() > max_warnings)
    std::printf("    ... %zu more warnings (--all-warnings shows them)\n",
                r.warnings.size() - max_warnings);
  std::fflush(stdout);
}

struct InfoOptions {
  std::vector<std::string> files;
  std::string xyz_columns;
  bool skip_missing = false;
  bool all_warnings = false;
};

int run_info(const InfoOptions& o) {
  int worst = 0;
  XyzOptions xyz;
  if (!o.xyz_columns.empty()) xyz.columns = parse_xyz_columns(o.xyz_columns);
  for (const auto& f : o.files) {
    try {
      describe(f, o.skip_missing, o.all_warnings ? static_cast<std::size_t>(-1) : 10, xyz);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "scanclean: error: %s\n", e.what());
      worst = std::max(worst, static_cast<int>(exit_code_for(e)));
    }
  }
  return worst;
}

const CommandRegistrar kRegistrar{{
    "info",
    "Describe point-cloud files: format, points, fields, grid, bounds, spacing, warnings",
    10,
    [](CLI::App& cmd) {
      auto o = std::make_shared<InfoOptions>();
      cmd.add_option("files", o->files,
                     "Point clouds (.ply .pcd .xyz .txt) or Stanford .conf sessions (merged)")
          ->required();
      cmd.add_flag("--skip-missing", o->skip_missing,
                   "For .conf files: describe the scans that exist and warn about missing ones "
                   "(default: a missing scan is an error)");
      cmd.add_flag("--all-warnings", o->all_warnings, "Print every reader warning (default: 10)");
      cmd.add_option("--xyz-columns", o->xyz_columns,
                     "Columns of .xyz/.txt files, e.g. x,y,z,r,g,b (default: guessed; the "
                     "'format' line says how the columns were found)");
      cmd.footer(
          "Prints, per file: format and encoding, point count (declared, kept, and invalid NaN/inf "
          "points dropped), fields as stored, organized size (rows x cols) for range images and "
          "organized PCD, bounding box and size, mean spacing (median nearest-neighbour distance "
          "over up to 10,000 evenly chosen points) and the reader's warnings.\n"
          "Units: PLY/PCD/XYZ carry no unit; lengths are printed in the file's unit, which is "
          "metres for the bundled data (Stanford and PCL scans).\n"
          "Every file is read even if an earlier one fails; the exit code is that of the worst "
          "failure: 0 ok, 3 bad input data, 4 file I/O failure.");
      add_report_option(cmd);
      return [o] { return run_info(*o); };
    },
}};

}  // namespace
}  // namespace scanclean::app

#endif  // SCANCLEAN_HAVE_IO

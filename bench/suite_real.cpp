// Real data: the merged Stanford bunny scans (with the normals of their range grids) before and
// after robust_filter (defaults, merging on), distance to the bun_zipper.ply reconstruction
// (metres); and one scan alone, with its grid's normals from a viewpoint (filter --viewpoint).
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <random>

#include "filter_run.h"
#include "suites.h"

#ifdef SCANCLEAN_BENCH_HAVE_REAL
#include "scanclean/eval/mesh_distance.h"
#include "scanclean/io/point_cloud_io.h"
#include "scanclean/io/range_grid_normals.h"
#include "scanclean/io/stanford_conf.h"
#include "scanclean/io/triangle_mesh_io.h"
#endif

namespace scanclean::bench {

#ifdef SCANCLEAN_BENCH_HAVE_REAL

namespace {
struct DistanceStats {
  double mean = 0, p95 = 0, rms = 0;
};

DistanceStats distance_stats(const MeshDistance& md, const std::vector<Eigen::Vector3d>& pts) {
  std::vector<double> d(pts.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, pts.size(), 1024),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      for (std::size_t i = r.begin(); i != r.end(); ++i) d[i] = md.distance(pts[i]);
                    });
  DistanceStats s;
  if (d.empty()) return s;
  double sum = 0, sq = 0;
  for (double v : d) {
    sum += v;
    sq += v * v;
  }
  s.mean = sum / d.size();
  s.rms = std::sqrt(sq / d.size());
  const std::size_t k =
      std::min(d.size() - 1, static_cast<std::size_t>(std::ceil(0.95 * d.size())) - 1);
  std::nth_element(d.begin(), d.begin() + static_cast<std::ptrdiff_t>(k), d.end());
  s.p95 = d[k];
  return s;
}

// robust_filter on `scan` three ways: without normals, with `normals` that only orient (as
// `scanclean filter --viewpoint` gives a grid's), and with `normals` as the kernels' normals.
std::array<FilterRun, 3> three_ways(const PointCloud& scan,
                                    const std::vector<Eigen::Vector3f>& normals,
                                    const FilterSettings& fs) {
  std::array<FilterRun, 3> runs;
  for (int k = 0; k < 3; ++k) {
    PointCloud c = scan;
    if (k > 0) c.normals = normals;
    FilterSettings f = fs;
    f.normals_orient_only = k == 1;
    runs[k] = run_robust_filter(c, f);
  }
  return runs;
}

// The share of c's normals that face `viewpoint`, as a percentage with one decimal.
std::string facing_share(const PointCloud& c, const Eigen::Vector3d& viewpoint) {
  std::size_t n = 0;
  for (std::size_t i = 0; i < c.size(); ++i)
    n += c.normals[i].cast<double>().dot(viewpoint - c.positions[i]) > 0 ? 1 : 0;
  return fmt_pct(static_cast<double>(n) / static_cast<double>(std::max<std::size_t>(1, c.size())),
                 1);
}

// One organized scan alone (bun000.ply, in bun_zipper.ply's frame): robust_filter without
// normals, with its grid's normals turned to face the scanner as `scanclean filter --viewpoint`
// gives them (they only orient), and with the same normals as the kernels' normals (as sensor
// normals), to show why --viewpoint does not use them so. "facing" is the share of output
// normals that face the viewpoint.
void single_scan_table(Context& ctx, const MeshDistance& md, const FilterSettings& fs) {
  const std::filesystem::path scan = ctx.bunny_conf.parent_path() / "bun000.ply";
  if (!std::filesystem::exists(scan)) {
    ctx.message("single-scan table skipped: " + scan.string() + " not found");
    return;
  }
  PointCloud cloud = read_point_cloud(scan);
  const Eigen::Vector3d viewpoint(0, 0, 1);  // the Cyberware scans look along -z of their frame
  const RangeGridNormals grid = range_grid_normals_from_viewpoint(cloud, viewpoint);
  Table t;
  t.title =
      "One organized scan with its grid's normals: bun000.ply alone vs bun_zipper.ply, and a "
      "range image of a sphere (distances in mm)";
  t.header = {"cloud", "points", "mean d mm", "p95 d mm", "RMS d mm", "normals facing the scanner",
              "time s"};
  const DistanceStats in = distance_stats(md, cloud.positions);
  t.rows.push_back({"bun000.ply (input)", fmt_count(cloud.size()), fmt(in.mean * 1e3, 4),
                    fmt(in.p95 * 1e3, 4), fmt(in.rms * 1e3, 4), "-", "-"});
  const char* names[3] = {"robust_filter, no normals",
                          "robust_filter, grid normals that orient (--viewpoint 0,0,1)",
                          "robust_filter, grid normals as the kernels' normals"};
  const std::array<FilterRun, 3> runs = three_ways(cloud, grid.normals, fs);
  for (int k = 0; k < 3; ++k) {
    const FilterRun& r = runs[k];
    const DistanceStats s = distance_stats(md, r.cloud.positions);
    t.rows.push_back({names[k], fmt_count(r.cloud.size()), fmt(s.mean * 1e3, 4),
                      fmt(s.p95 * 1e3, 4), fmt(s.rms * 1e3, 4), facing_share(r.cloud, viewpoint),
                      fmt(r.seconds_wall, 2)});
  }
  // The same three on a depth camera's range image (synthetic: exact distances): a camera at
  // the origin looking along +z at a sphere of radius 0.3 m centred 1 m away, 240 x 240 pixels
  // 1.5 mm apart at 1 m, 1 mm Gaussian noise along the rays (seed ctx.seed).
  {
    const Eigen::Vector3d centre(0, 0, 1);
    constexpr double kRadius = 0.3;
    constexpr int kSide = 240;
    PointCloud image;
    image.grid.rows = image.grid.cols = kSide;
    image.grid.index.assign(static_cast<std::size_t>(kSide) * kSide, -1);
    std::mt19937 rng(static_cast<std::uint32_t>(ctx.seed));
    std::normal_distribution<double> noise(0.0, 0.001);
    for (int r = 0; r < kSide; ++r)
      for (int c = 0; c < kSide; ++c) {
        const Eigen::Vector3d ray =
            Eigen::Vector3d((c - kSide / 2) * 0.0015, (r - kSide / 2) * 0.0015, 1).normalized();
        const double b = ray.dot(centre), disc = b * b - (centre.squaredNorm() - kRadius * kRadius);
        if (disc <= 0) continue;
        image.grid.index[static_cast<std::size_t>(r) * kSide + c] =
            static_cast<std::int32_t>(image.size());
        image.positions.push_back((b - std::sqrt(disc) + noise(rng)) * ray);
      }
    const RangeGridNormals in = range_grid_normals_from_viewpoint(image, Eigen::Vector3d::Zero());
    auto rms = [&](const PointCloud& c) {
      double s = 0;
      for (const auto& p : c.positions) s += std::pow((p - centre).norm() - kRadius, 2);
      return std::sqrt(s / static_cast<double>(std::max<std::size_t>(1, c.size())));
    };
    t.rows.push_back({"sphere range image (synthetic, 1 mm noise): input", fmt_count(image.size()),
                      "-", "-", fmt(rms(image) * 1e3, 4), "-", "-"});
    const char* sphere_names[3] = {
        "sphere range image: robust_filter, no normals",
        "sphere range image: grid normals that orient (--viewpoint 0,0,0)",
        "sphere range image: grid normals as the kernels' normals"};
    const std::array<FilterRun, 3> sphere_runs = three_ways(image, in.normals, fs);
    for (int k = 0; k < 3; ++k) {
      const FilterRun& r = sphere_runs[k];
      t.rows.push_back({sphere_names[k], fmt_count(r.cloud.size()), "-", "-",
                        fmt(rms(r.cloud) * 1e3, 4), facing_share(r.cloud, Eigen::Vector3d::Zero()),
                        fmt(r.seconds_wall, 2)});
    }
    t.notes.push_back(
        "Sphere range image rows: RMS of the distances to the exact sphere (mm); "
        "the grid gives " +
        fmt_count(in.with_normal) + " of " + fmt_count(image.size()) + " points a normal.");
  }
  t.notes.push_back(
      "The grid's normals (range_grid_normals_from_viewpoint, viewpoint (0, 0, 1) m): " +
      fmt_count(grid.with_normal) + " of " + fmt_count(cloud.size()) + " points, " +
      fmt_count(grid.facing) + " of them facing it.");
  ctx.add(std::move(t));
}
}  // namespace

void run_real_suite(Context& ctx) {
  if (!std::filesystem::exists(ctx.bunny_conf)) {
    ctx.message("real-data section skipped: " + ctx.bunny_conf.string() +
                " not found (../shared absent)");
    return;
  }
  if (!filter_available()) {
    ctx.message("real-data section skipped: robust_filter is not part of this build");
    return;
  }
  ReadReport report;
  ConfOptions conf_options;
  conf_options.skip_missing = true;  // the bundled bun.conf lists scans that are not shipped
  PointCloud merged = read_and_merge_conf(ctx.bunny_conf, &report, conf_options);
  const TriangleMesh mesh = read_triangle_mesh(ctx.bunny_mesh);
  const MeshDistance md(mesh);
  FilterSettings fs;
  fs.merge = true;
  fs.threads = ctx.threads;
  fs.refit_spread = ctx.refit_spread;
  fs.crease_spread = ctx.crease_spread;
  fs.orient_k = ctx.orient_normals;
  fs.cgal_orient_k = ctx.cgal_orient_normals;
  fs.scale_regions = ctx.scale_regions;
  fs.k_h = ctx.k_h;
  fs.scale_gamma = ctx.scale_gamma;
  fs.passes = ctx.passes;
  FilterRun run = run_robust_filter(merged, fs);
  const DistanceStats before = distance_stats(md, merged.positions);
  const DistanceStats after = distance_stats(md, run.cloud.positions);
  // Input points the filter removed (neither kept nor merged into a kept point).
  auto removed = [](const FilterRun& r) {
    std::size_t kept = 0;
    for (auto k : r.kept) kept += k;
    return r.kept.size() - kept;
  };
  const std::size_t removed_inputs = removed(run);

  Table t;
  t.title = "Real data: merged Stanford bunny scans vs bun_zipper.ply (distances in mm)";
  t.header = {"cloud", "points", "mean d mm", "p95 d mm", "RMS d mm", "time s"};
  t.rows.push_back({"merged scans (input)", fmt_count(merged.size()), fmt(before.mean * 1e3, 3),
                    fmt(before.p95 * 1e3, 3), fmt(before.rms * 1e3, 3), "-"});
  t.rows.push_back({"robust_filter output", fmt_count(run.cloud.size()), fmt(after.mean * 1e3, 3),
                    fmt(after.p95 * 1e3, 3), fmt(after.rms * 1e3, 3), fmt(run.seconds_wall, 2)});
  t.notes.push_back("robust_filter settings: " + fs.describe() + "; h = " + fmt(run.h * 1e3, 3) +
                    " mm, estimated noise sigma = " + fmt(run.noise_sigma * 1e3, 3) + " mm.");
  t.notes.push_back(
      "Input points removed as outliers: " + fmt_count(removed_inputs) + " (unsupported " +
      fmt_count(run.unsupported) + ", off surface " + fmt_count(run.off_surface) +
      ", low density " + fmt_count(run.low_density) + ", low likelihood " +
      fmt_count(run.low_likelihood) + ", displaced " + fmt_count(run.displaced) +
      ", small components " + fmt_count(run.small_components) + "; " +
      fmt_pct(static_cast<double>(removed_inputs) / static_cast<double>(merged.size()), 2) +
      "); merged into other output points: " + fmt_count(run.merged) +
      "; kernels split at creases: " + fmt_count(run.kernels_split) +
      ", refitted on their own sheet: " + fmt_count(run.kernels_refitted) + ", of " +
      fmt_count(run.kernels) + ".");
  // The same without the normals of the scans' range grids (ConfOptions::scan_normals; the
  // filter then fits every kernel to all its neighbours, whichever way they face).
  {
    PointCloud bare = merged;
    bare.normals.clear();
    const FilterRun rb = run_robust_filter(bare, fs);
    const DistanceStats db = distance_stats(md, rb.cloud.positions);
    const std::size_t removed_bare = removed(rb);
    t.rows.push_back({"robust_filter output without the scans' normals", fmt_count(rb.cloud.size()),
                      fmt(db.mean * 1e3, 3), fmt(db.p95 * 1e3, 3), fmt(db.rms * 1e3, 3),
                      fmt(rb.seconds_wall, 2)});
    t.notes.push_back(
        "Without the scans' normals: h = " + fmt(rb.h * 1e3, 3) + " mm, noise sigma " +
        fmt(rb.noise_sigma * 1e3, 3) + " mm, " + fmt_count(removed_bare) + " points removed (" +
        fmt_pct(static_cast<double>(removed_bare) / static_cast<double>(bare.size()), 2) + ").");
  }
  // The setting of the 2.1M-point speed target (adaptive k = 250), with its automatic kernel
  // stride (2) and with a kernel at every point, on the same real scans.
  for (const int stride : {0, 1}) {
    FilterSettings fa = fs;
    fa.adaptive = true;
    fa.k_adaptive = 250;
    fa.kernel_stride = stride;
    const FilterRun ra = run_robust_filter(merged, fa);
    const DistanceStats da = distance_stats(md, ra.cloud.positions);
    t.rows.push_back({"robust_filter output (" + fa.describe() + ")", fmt_count(ra.cloud.size()),
                      fmt(da.mean * 1e3, 3), fmt(da.p95 * 1e3, 3), fmt(da.rms * 1e3, 3),
                      fmt(ra.seconds_wall, 2)});
  }
  for (const auto& w : report.warnings) t.notes.push_back("reader: " + w);
  t.notes.push_back(
      "bun_zipper.ply is Stanford's reconstruction from these scans, not an independent ground "
      "truth: distances measure agreement with it.");
  ctx.add(std::move(t));
  single_scan_table(ctx, md, fs);
}

#else

void run_real_suite(Context& ctx) {
  ctx.message(
      "real-data section skipped: scanclean_bench was built without the io/eval modules "
      "(read_and_merge_conf, MeshDistance)");
}

#endif

}  // namespace scanclean::bench

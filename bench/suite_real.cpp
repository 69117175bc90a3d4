// Real data: the merged Stanford bunny scans (with the normals of their range grids) before and
// after robust_filter (defaults, merging on), distance to the bun_zipper.ply reconstruction
// (metres).
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <iostream>

#include "filter_run.h"
#include "suites.h"

#ifdef SCANCLEAN_BENCH_HAVE_REAL
#include "scanclean/eval/mesh_distance.h"
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
  fs.orient_k = ctx.orient_normals;
  fs.scale_regions = ctx.scale_regions;
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
      "; kernels refitted on their own plane: " + fmt_count(run.kernels_refitted) + " of " +
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
}

#else

void run_real_suite(Context& ctx) {
  ctx.message(
      "real-data section skipped: scanclean_bench was built without the io/eval modules "
      "(read_and_merge_conf, MeshDistance)");
}

#endif

}  // namespace scanclean::bench

// scanclean_bench: the evaluation protocol of docs/ALGORITHM.md, scanclean's robust_filter side
// by side with CGAL's smoothers, a PCA-plane baseline and classical outlier removal, plus speed,
// memory and the real merged bunny scans. See bench/README.md.
#include <tbb/global_control.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <memory>
#include <sstream>

#include "filter_run.h"
#include "scanclean/core/atomic_file.h"
#include "scanclean/core/errors.h"
#include "scanclean/core/process_memory.h"
#include "suites.h"

#ifndef SCANCLEAN_SOURCE_DIR
#define SCANCLEAN_SOURCE_DIR "."
#endif
#ifndef SCANCLEAN_BENCH_SHARED_DATA_DIR
#define SCANCLEAN_BENCH_SHARED_DATA_DIR SCANCLEAN_SOURCE_DIR "/../shared/data"
#endif

namespace scanclean::bench {

void Context::add(Table t) {
  std::cout << t.markdown() << std::flush;
  tables.push_back(std::move(t));
}

void Context::message(const std::string& m) {
  std::cout << "NOTE: " << m << "\n" << std::flush;
  messages.push_back(m);
}

std::vector<std::unique_ptr<Shape>> protocol_shapes(Context& ctx) {
  std::vector<std::unique_ptr<Shape>> shapes;
  shapes.push_back(make_sphere());
  if (ctx.quick) return shapes;
  shapes.push_back(make_torus());
  shapes.push_back(make_rounded_box());
  try {
    shapes.push_back(make_mesh_shape(ctx.bunny_mesh, "bunny"));
  } catch (const std::exception& e) {
    static bool told = false;
    if (!told) ctx.message(std::string("bunny mesh left out: ") + e.what());
    told = true;
  }
  return shapes;
}

}  // namespace scanclean::bench

namespace {

int run(int argc, char** argv) {
  using namespace scanclean;
  using namespace scanclean::bench;
  CLI::App app{
      "scanclean_bench: the point-cloud denoising evaluation protocol (docs/ALGORITHM.md) with "
      "scanclean's robust_filter beside CGAL jet/bilateral/WLOP, a PCA-plane projection and "
      "statistical outlier removal; speed and memory; the real merged Stanford bunny scans.\n"
      "Quality numbers are in unit-sphere units (shapes normalised to radius 1); CD and P2M are "
      "mean squared distances x 1e4."};
  bool quick = false;
  std::string suite = "all";
  int threads = 0;
  std::uint64_t seed = 1;
  std::string out;
  std::string speed_child;
  std::size_t speed_n = 0;
  std::string bunny_mesh = std::string(SCANCLEAN_SOURCE_DIR) + "/recordings/bunny/bun_zipper.ply";
  std::string bunny_conf =
      std::string(SCANCLEAN_BENCH_SHARED_DATA_DIR) + "/stanford_bunny/data/bun.conf";
  app.add_flag(
      "--quick", quick,
      "small smoke run (under a minute): the sphere only, 10k points, sigma 0.02, no WLOP; "
      "5 % uniform outliers; speed of robust_filter, PCA and SOR at 100k; real data");
  app.add_option("--suite", suite, "which sections to run")
      ->check(CLI::IsMember({"quality", "outliers", "speed", "real", "mesh", "all"}))
      ->capture_default_str();
  app.add_option("--threads", threads, "worker threads for every method (0 = all cores)")
      ->check(CLI::Range(0, 1024))
      ->capture_default_str();
  app.add_option("--seed", seed, "base seed of every random input")->capture_default_str();
  app.add_option("--out", out, "also write the report as Markdown to this file (atomic write)");
  app.add_option("--bunny-mesh", bunny_mesh, "ground-truth mesh (PLY)")->capture_default_str();
  app.add_option("--bunny-conf", bunny_conf, "Stanford .conf of the real bunny scans")
      ->capture_default_str();
  bool self_test = false;
  std::size_t tune_n = 0;
  app.add_flag("--self-test", self_test,
               "check the harness itself (sampling, noise, metrics, outlier labels, baselines) "
               "against known answers and exit (0 = all passed)");
  app.add_option("--tune", tune_n,
                 "print the peers' CD/P2M over a grid of neighbourhood sizes at this N on a "
                 "tuning set (seed + 1000) and exit");
  std::size_t wlop_max_n = 10000;
  app.add_option("--wlop-max-n", wlop_max_n,
                 "run CGAL WLOP (slow) only for N up to this (0 = at every size)")
      ->capture_default_str();
  double tune_sigma = 0;
  app.add_option("--tune-sigma", tune_sigma, "with --tune: only this noise level (0 = all)");
  std::vector<std::size_t> sizes;
  std::vector<double> sigmas;
  bool filter_only = false;
  app.add_option("--sizes", sizes, "quality suite: only these point counts (default 10000 50000)")
      ->check(CLI::Range(std::size_t{100}, std::size_t{10000000}));
  app.add_option("--sigmas", sigmas,
                 "quality suite: only these noise levels (default 0.01 0.02 0.03)")
      ->check(CLI::Range(0.0, 0.2));
  app.add_flag("--filter-only", filter_only,
               "quality suite: run robust_filter alone, without the peers (for quick experiments; "
               "no target check)");
  std::vector<std::string> shape_names;
  app.add_option("--shapes", shape_names,
                 "quality suite: only these shapes (sphere torus rounded_box bunny; the known "
                 "limits: thin_plate sharp_box cad_block two_scale)");
  double refit_spread = -1;
  app.add_option("--refit-spread", refit_spread,
                 "quality and real suites: robust_filter's refit_spread (default: the library's)");
  double crease_spread = -1;
  app.add_option("--crease-spread", crease_spread,
                 "quality and real suites: robust_filter's crease_spread (default: the "
                 "library's; 0 = the split off)");
  // 0 (off) or K in [6, 200], for both orientation options.
  const CLI::Validator orient_range(
      [](std::string& s) {
        char* end = nullptr;
        const long k = std::strtol(s.c_str(), &end, 10);
        const bool ok = end != s.c_str() && *end == '\0' && (k == 0 || (k >= 6 && k <= 200));
        return ok ? std::string() : "expected 0 (off) or an integer in [6, 200], got " + s;
      },
      "0 or K in [6, 200]");
  int orient_normals = 0;
  app.add_option("--orient-normals", orient_normals,
                 "quality and real suites: robust_filter orients normals first (PCA over K "
                 "neighbours, spanning forest over 12; FilterOptions::orient_k), as scanclean "
                 "filter --orient-normals K; 0 (off) or K in [6, 200]")
      ->check(orient_range);
  int cgal_orient_normals = 0;
  app.add_option("--orient-normals-cgal", cgal_orient_normals,
                 "quality and real suites, for comparison: CGAL's normals first (PCA over K "
                 "neighbours, MST over K / 2), given to robust_filter as normals that only "
                 "orient; 0 (off) or K in [6, 200]")
      ->check(orient_range);
  int scale_regions = 0;
  app.add_option("--scale-regions", scale_regions,
                 "quality and real suites: robust_filter's scale_regions (a scale per region, "
                 "as scanclean filter --scale-regions K; 0 = one h for the cloud)")
      ->check(CLI::Range(0, 256));
  int k_h = 0;
  app.add_option("--k-h", k_h,
                 "quality, real and speed suites: robust_filter's K_h (as scanclean filter --k-h; "
                 "0 = the library's default), to measure what it trades")
      ->check(CLI::Range(0, 1000));
  double scale_gamma = -1;
  app.add_option("--scale-gamma", scale_gamma,
                 "quality and real suites: robust_filter's scale_gamma (the scale test, as "
                 "scanclean filter --scale-gamma; default: the library's; 0 = the test off)")
      ->check(CLI::Range(0.0, 20.0));
  int passes = 0;
  app.add_option("--passes", passes,
                 "quality and real suites: robust_filter's passes (as scanclean filter --passes: 2 "
                 "refits the kernels on the first pass's output and projects again; 0 = the "
                 "library's default)")
      ->check(CLI::Range(0, 2));
  std::string pictures;
  app.add_option("--pictures", pictures, "mesh suite: write its pictures (PNG) into this folder");
  app.add_option("--speed-child", speed_child, "internal: run one speed measurement")->group("");
  app.add_option("--speed-n", speed_n, "internal: points of the speed measurement")->group("");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : static_cast<int>(ExitCode::kBadOptions);
  }
  if (self_test) return self_test_main(seed);
  if (tune_n > 0) return tune_main(tune_n, seed + 1000, tune_sigma, bunny_mesh);
  if (!speed_child.empty()) return speed_child_main(speed_child, speed_n, seed, threads, k_h);

  std::unique_ptr<tbb::global_control> limit;
  if (threads > 0)
    limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                  static_cast<std::size_t>(threads));
  Context ctx;
  ctx.quick = quick;
  ctx.threads = threads;
  ctx.seed = seed;
  ctx.wlop_max_n = wlop_max_n;
  ctx.sizes = sizes;
  ctx.sigmas = sigmas;
  ctx.filter_only = filter_only;
  ctx.shape_names = shape_names;
  ctx.refit_spread = refit_spread;
  ctx.crease_spread = crease_spread;
  ctx.orient_normals = orient_normals;
  ctx.cgal_orient_normals = cgal_orient_normals;
  ctx.scale_regions = scale_regions;
  ctx.k_h = k_h;
  ctx.scale_gamma = scale_gamma;
  ctx.passes = passes;
  ctx.self_exe = std::filesystem::read_symlink("/proc/self/exe");
  ctx.bunny_mesh = bunny_mesh;
  ctx.bunny_conf = bunny_conf;
  ctx.pictures_dir = pictures;

  const MachineInfo mi = machine_info();
  std::ostringstream head;
  head << "# scanclean benchmark\n\n";
  head << "- Command: `";
  for (int i = 0; i < argc; ++i) head << (i ? " " : "") << argv[i];
  head << "`\n- Date: " << mi.date_utc << "\n- Machine: " << mi.cpu_model << ", " << mi.cores
       << " hardware threads; threads used: " << (threads ? std::to_string(threads) : "all")
       << "\n- scanclean commit: " << mi.commit << "; compiler: " << mi.compiler
       << "\n- CGAL 5.5 (Debian libcgal-dev, header-only) with CGAL::Parallel_if_available_tag "
          "and TBB linked, i.e. parallel, under the same thread limit\n- Seed: "
       << seed << (quick ? "; QUICK smoke run (subset)" : "") << "\n\n";
  std::cout << head.str() << std::flush;

  const auto t0 = std::chrono::steady_clock::now();
  if (!filter_available())
    ctx.message("robust_filter is not part of this build (filter module missing)");
  if (suite == "quality" || suite == "all") run_quality_suite(ctx);
  if (suite == "outliers" || suite == "all") run_outlier_suite(ctx);
  if (suite == "speed" || suite == "all") run_speed_suite(ctx);
  if (suite == "real" || suite == "all") run_real_suite(ctx);
  if (suite == "mesh" || suite == "all") run_mesh_suite(ctx);
  const double total = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  std::ostringstream summary;
  summary << "Total benchmark time: " << total << " s.\n";
  std::cout << summary.str();
  if (!out.empty()) {
    write_file_atomically(
        out,
        [&](std::ostream& os) {
          os << head.str();
          if (!ctx.messages.empty()) {
            os << "## Remarks\n\n";
            for (const auto& m : ctx.messages) os << "- " << m << "\n";
            os << "\n";
          }
          for (const auto& t : ctx.tables) os << t.markdown();
          os << summary.str();
        },
        false);
    std::cout << "Report written to " << out << "\n";
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  // As the programs do: every method the suites time, ours and the peers', runs with it.
  scanclean::keep_freed_arrays_for_reuse();
  try {
    return run(argc, argv);
  } catch (const std::exception& e) {
    std::cerr << "scanclean_bench: error: " << e.what() << "\n";
    return static_cast<int>(scanclean::exit_code_for(e));
  }
}

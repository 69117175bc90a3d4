#pragma once
//! \file suites.h
//! The benchmark's sections. Each appends its tables to the context (and prints them at once).

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "report.h"
#include "shapes.h"

namespace scanclean::bench {

struct Context {
  bool quick = false;
  int threads = 0;  //!< 0 = all cores
  std::uint64_t seed = 1;
  std::filesystem::path self_exe;    //!< this program (speed runs re-execute it)
  std::filesystem::path bunny_mesh;  //!< recordings/bunny/bun_zipper.ply
  std::filesystem::path bunny_conf;  //!< ../shared/data/stanford_bunny/data/bun.conf
  std::size_t wlop_max_n = 10000;    //!< WLOP (slow) runs only up to this N (0 = always)
  std::vector<std::size_t> sizes;    //!< quality suite: only these N (empty = the protocol's)
  std::vector<double> sigmas;        //!< quality suite: only these noise levels (empty = all)
  bool filter_only = false;          //!< quality suite: robust_filter alone (no peers)
  //! quality suite: only these shapes (empty = all)
  std::vector<std::string> shape_names;
  //! quality and real suites: FilterOptions::refit_spread (< 0: the library's default)
  double refit_spread = -1;
  //! quality and real suites: FilterOptions::crease_spread (< 0: the library's default)
  double crease_spread = -1;
  //! quality and real suites: FilterOptions::orient_k (FilterSettings::orient_k; 0: off)
  int orient_normals = 0;
  //! quality and real suites: CGAL's normals first (FilterSettings::cgal_orient_k; 0: off)
  int cgal_orient_normals = 0;
  //! quality and real suites: FilterOptions::scale_regions (0: one h for the cloud)
  int scale_regions = 0;
  //! quality, real and speed suites: FilterOptions::k_h (0: the library's default)
  int k_h = 0;
  //! quality and real suites: FilterOptions::scale_gamma (< 0: the library's default)
  double scale_gamma = -1;
  //! quality and real suites: FilterOptions::passes (0: the library's default)
  int passes = 0;
  //! mesh suite: write its PNG pictures into this folder (empty: none)
  std::filesystem::path pictures_dir;
  std::vector<Table> tables;
  std::vector<std::string> messages;  //!< skipped parts and other remarks for the report
  void add(Table t);
  void message(const std::string& m);
};

//! Settings of the peer methods for one noise level (sigma in normalised units).
struct PeerSettings {
  unsigned jet_k = 0;
  unsigned bilateral_k = 0;
  double bilateral_sharpness = 0;
  int bilateral_iterations = 0;
  double wlop_select_percentage = 0;
  unsigned wlop_iterations = 0;
  int pca_k = 0;
};
PeerSettings peer_settings(double sigma, std::size_t n);

//! The protocol's shapes (quick: the sphere only). The bunny is added when the build has io/eval
//! and the mesh file exists; otherwise a message says why not.
std::vector<std::unique_ptr<Shape>> protocol_shapes(Context& ctx);

void run_quality_suite(Context& ctx);
void run_outlier_suite(Context& ctx);
void run_speed_suite(Context& ctx);
void run_real_suite(Context& ctx);
void run_mesh_suite(Context& ctx);

//! --self-test: checks of the harness against oracles; returns the exit code (0 = all passed).
int self_test_main(std::uint64_t seed);
//! --tune: the peers' neighbourhood sizes on a tuning set (seed distinct from the protocol's).
int tune_main(std::size_t n, std::uint64_t seed, double only_sigma,
              const std::filesystem::path& bunny);

//! Entry point of a speed measurement child process (see suite_speed.cpp). Returns the exit code.
//! k_h: FilterOptions::k_h for the filter's runs (0: the library's default).
int speed_child_main(const std::string& method, std::size_t n, std::uint64_t seed, int threads,
                     int k_h);

}  // namespace scanclean::bench

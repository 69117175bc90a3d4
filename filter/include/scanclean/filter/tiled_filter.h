#pragma once
//! \file tiled_filter.h
//! The robust filter (robust_filter.h) out of core: for clouds larger than memory, and for many
//! processes (MPI) sharing one cloud.
//!
//! Passes over the input, each reading it by record ranges (one range per process):
//!  1. the bounding box, the point count and the sample of the automatic h (the records
//!     k N / 10,000, as robust_filter samples them);
//!  2. a coarse occupancy histogram over the box, and the squared distances from every sample to
//!     its neighbours (the K_h-th neighbour distance h0 exactly as robust_filter computes it, and
//!     its first rough estimate r_est, which sizes robust_filter's first point index);
//!  3. the neighbourhoods of every 4th sample, from which the noise estimate and the scale test
//!     run as in robust_filter (the same function, noise_scale.h), giving h for the whole cloud
//!     (repeated with a wider radius if the first did not reach far enough);
//!  4. (kernel stride > 1) the points per cell of the grid robust_filter's kernel phase uses on
//!     the whole cloud, so that every point's place in the whole cloud's grid order, hence
//!     whether it carries a kernel, is known (exchanged between the processes);
//!  5. the points are sorted into tiles: boxes cut from the histogram so that each tile, with a
//!     halo of halo_factor x h on every side, holds at most the points the memory budget allows;
//!     each point goes, marked as kernel site or not, to a scratch file of its own tile and of
//!     every tile whose halo holds it;
//!  6. each tile (its points in input order, halo included) is filtered with the global choices
//!     of pass 3 (h, kernel stride, merging distance, minimum component size) and the kernel
//!     sites of pass 4, and the output points and outliers whose seed lies in the tile's own box
//!     are handed to the sink.
//! Tiles are planned from global data only and each is filtered alone, deterministically, so the
//! result does not depend on the number of processes or threads.
//!
//! Against robust_filter on the whole cloud: h0 and the kernel sites are the same; the noise
//! estimate and the scale test sum the same neighbours in another order (differences of a few
//! ulps in h). Within a tile, the grids are anchored at the tile's own points, so sums run in
//! another order (positions differ in the last bits), the density test's thinning of the output
//! points (every stride-th in their grid order) and its medians (tau) are the tile's, and
//! clusters at tile borders are seeded on each side: a few density decisions near the threshold
//! differ (docs/SCALING.md). Coincident copies and far points (robust_filter filters them apart)
//! shift the kernel sites. The tests and the scaling benchmark report the differences (count and
//! largest distance).

#include <Eigen/Geometry>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "scanclean/core/point_cloud.h"
#include "scanclean/filter/filter_options.h"
#include "scanclean/filter/robust_filter.h"

namespace scanclean {

//! The input, read by record ranges: read(first, count, out, records) fills `out` with the
//! points of records [first, first + count) that are valid (finite) and `records` with their
//! record numbers. Must be callable from any thread (see io/point_stream.h).
struct TiledSource {
  std::uint64_t records = 0;
  //! The attributes every read() fills, in this order (name, type; PointStream::attributes()):
  //! the tiles carry them to the outputs as the in-memory filter does.
  std::vector<std::pair<std::string, AttributeType>> attributes;
  std::function<void(std::uint64_t first, std::uint64_t count, PointCloud& out,
                     std::vector<std::uint64_t>& records)>
      read;
};

//! Cooperation between processes (MPI). The default is one process.
struct TileComm {
  int rank = 0;
  int ranks = 1;
  //! Every process passes its bytes; every process gets all of them concatenated in rank order.
  //! Null for one process.
  std::function<std::string(const std::string&)> allgather;
  //! Optional: every process passes counts of the same length and gets, in place, their sums
  //! over the processes (MPI_Allreduce). The occupancy histogram travels this way when the cells
  //! the processes occupy, gathered, would outweigh the whole array; without it, or below that,
  //! through allgather as the occupied cells.
  std::function<void(std::vector<std::uint64_t>&)> sum;
  //! Optional: a counter the processes share, from 0 for each run (MPI_Fetch_and_op on process
  //! 0's memory): each call returns the next value to exactly one caller. With it, the
  //! processes take the tiles one at a time, largest first, each as it becomes free; without
  //! it, the plan deals them out beforehand (largest first, to the least loaded). Either way the
  //! results are the same; only which process filters which tile differs.
  std::function<std::uint64_t()> take;
};

//! Options of the tiled run. Checked by validate().
struct TiledOptions {
  //! Peak resident memory the run aims for (bytes), >= 64 MiB. Tiles are sized from it.
  std::size_t memory_budget = std::size_t{2} << 30;
  double halo_factor = 4.0;             //!< halo width in h, [1, 20]
  std::filesystem::path scratch;        //!< folder for the tiles' scratch files (must exist)
  std::size_t chunk_records = 1 << 20;  //!< records per read
  //! > 0: at most this many points per tile, halo included (tests, benchmarks); 0 = from the
  //! budget (tile_point_limit).
  std::uint64_t max_tile_points = 0;
  //! Optional progress report (phase, fraction); called from the calling thread.
  std::function<void(const std::string&, double)> progress;
  //! Optional: called once with the global choices, before the first tile (e.g. to open the
  //! outputs, whose position type depends on the bounding box).
  std::function<void(const struct TiledGlobals&)> on_globals;
};

//! Throws OptionError naming the option when out of range.
void validate(const TiledOptions& options);

//! Points a tile may hold (halo included) under the budget: what the filter needs per point,
//! measured (docs/SCALING.md), plus 24 bytes per point for each attribute the input carries
//! (three copies of a double).
std::uint64_t tile_point_limit(std::size_t memory_budget, std::size_t attributes = 0);

//! Bytes the in-memory filter is expected to need for n points with that many attributes (for
//! the decision to tile).
std::uint64_t in_memory_bytes(std::uint64_t points, std::size_t attributes = 0);

//! The global choices every tile makes the same (pass 1-3).
struct TiledGlobals {
  std::uint64_t points = 0;  //!< valid points of the input
  Eigen::AlignedBox3d box;   //!< bounding box (metres)
  double h = 0, h0 = 0, noise_sigma = 0, noise_sigma_h0 = 0, h_noise = 0;
  double mean_spacing = 0, merge_eps = 0;
  int kernel_stride = 1;
  std::size_t min_component_size = 0;
  double halo = 0;  //!< halo width (metres)
};

//! One tile of the plan: its own box (points inside it belong to it) and its point counts.
struct TilePlanEntry {
  Eigen::AlignedBox3d box;
  std::uint64_t own_points = 0;  //!< points in the box (histogram count)
  std::uint64_t with_halo = 0;   //!< estimate of the points with the halo (histogram cells)
  int rank = 0;                  //!< the process that filters it
};

struct TiledStats {
  TiledGlobals globals;
  std::size_t tiles = 0;
  std::uint64_t points_in = 0, points_out = 0, outliers = 0, unsupported = 0, merged = 0;
  std::uint64_t halo_points = 0;      //!< points filtered as halo (this process)
  std::uint64_t tile_points_max = 0;  //!< most points in one tile, halo included
  std::size_t tiles_here = 0;         //!< tiles filtered by this process
  double seconds_globals = 0, seconds_distribute = 0, seconds_tiles = 0, seconds_total = 0;
  std::size_t peak_rss_bytes = 0;
};

//! Receives the result of each tile this process filters: the output points and the removed
//! points whose seeds lie in the tile's own box (source_index = record number). In tile order,
//! except when the processes take the tiles as they become free (TileComm::take: largest
//! first).
using TileSink =
    std::function<void(std::size_t tile, const PointCloud& cloud, const PointCloud& outliers)>;

//! Runs the filter tile by tile (see the file comment). Every process of `comm` calls it with
//! the same arguments. \throw OptionError; InputError for a non-finite coordinate or a weight
//! outside [0, 1], naming the record, from the first pass (before any tile reaches the sink);
//! IoError (scratch). A run ended by an exception, the sink's included, removes the scratch
//! files: with several processes, those of every process (the others, waiting for this one in
//! their next exchange, cannot finish; scanclean-mpi aborts them).
TiledStats tiled_filter(const TiledSource& source, const FilterOptions& options,
                        const TiledOptions& tiled, const TileSink& sink, const TileComm& comm = {});

}  // namespace scanclean

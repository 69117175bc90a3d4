#pragma once
//! Internal: the first passes of a tiled run (tiled_filter.h), which make the choices every tile
//! then shares: the box, the point count and the arrays present; the occupancy histogram; the
//! automatic h as the in-memory filter computes it (tile_scale.h); and what follows from them
//! (merging distance, kernel stride, minimum component size, halo).

#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "scanclean/filter/filter_options.h"
#include "scanclean/filter/tiled_filter.h"
#include "tile_plan.h"
#include "tile_scratch.h"

namespace scanclean::detail {

struct GlobalPasses {
  TiledGlobals globals;    //!< points = 0: the input holds no valid point (nothing else is set)
  ScratchColumns columns;  //!< the arrays any process's records carry, and the attributes
  TileGrid grid;           //!< the occupancy histogram's grid (occupancy_grid of the box)
  std::vector<std::uint64_t> histogram;  //!< points per cell of `grid`
  //! The automatic h (kAuto): the rough K-th neighbour distance that sizes the in-memory run's
  //! first point index (scale.h), for kernel_site_cell (tile_sites.h); else 0.
  double r_est = 0;
};

//! Passes 1-3 over this process's records `range` (record_range), `chunk` records at a time, in
//! step with every other process of `comm`. Validates each chunk as robust_filter does
//! (input_checks.h). \throw InputError naming the record; OptionError.
GlobalPasses global_passes(const TiledSource& src, const FilterOptions& o, double halo_factor,
                           std::array<std::uint64_t, 2> range, std::size_t chunk,
                           const TileComm& comm,
                           const std::function<void(const std::string&, double)>& progress);

}  // namespace scanclean::detail

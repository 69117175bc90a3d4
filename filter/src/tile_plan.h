#pragma once
//! Internal: the tiles of a tiled run (tiled_filter.h), planned from a coarse occupancy
//! histogram of the whole cloud: boxes of whole histogram cells, cut by recursive bisection
//! until each, grown by the halo, holds at most the points the memory budget allows, and dealt
//! to the processes. The plan depends on global data only (the box, the histogram, the halo),
//! so every process makes the same one.

#include <Eigen/Geometry>
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "scanclean/filter/tiled_filter.h"

namespace scanclean::detail {

//! The occupancy histogram's grid over the cloud's bounding box.
struct TileGrid {
  Eigen::Vector3d lo = Eigen::Vector3d::Zero();
  double cell = 1;
  std::array<std::int64_t, 3> dims{1, 1, 1};
  std::size_t cells() const { return static_cast<std::size_t>(dims[0] * dims[1] * dims[2]); }
  //! The cell of p, clamped to the grid (a point outside the box takes the nearest cell).
  std::array<std::int64_t, 3> cell_of(const Eigen::Vector3d& p) const;
  //! The cell's number, x fastest.
  std::size_t flat(const std::array<std::int64_t, 3>& c) const {
    return static_cast<std::size_t>((c[2] * dims[1] + c[1]) * dims[0] + c[0]);
  }
};

//! The histogram's grid over `box`: cubic cells, about 2 million over the box's volume (each
//! extent at least a millionth of the largest), at most 256 along the longest side; one cell
//! for a box of a single location.
TileGrid occupancy_grid(const Eigen::AlignedBox3d& box);

//! Cells [lo, hi) of the grid: lo x, y, z, then hi x, y, z.
using CellBox = std::array<std::int64_t, 6>;

struct TilePlan {
  TileGrid grid;
  std::vector<TilePlanEntry> tiles;  //!< in tile order (the bisection's leaves, depth first)
  std::vector<CellBox> cells;        //!< per tile: its cells
  std::vector<std::uint32_t> tile_of_cell;
  std::int64_t halo_cells = 1;  //!< the halo in whole cells (at least one)
  //! The tile whose own box holds p (by its histogram cell).
  std::uint32_t tile_of(const Eigen::Vector3d& p) const {
    return tile_of_cell[grid.flat(grid.cell_of(p))];
  }
};

//! The plan for the histogram `hist` of `grid` (points per cell, grid.flat order): every
//! occupied cell in exactly one tile; a box is cut (at the cut, on any axis, whose larger half
//! with the halo holds the fewest points) while, grown by `halo` (metres, rounded up to whole
//! cells), it holds more than `limit` points, unless no cut takes at least a sixteenth off;
//! boxes without points are dropped. Tiles go to `ranks` processes, the largest first, each to
//! the least loaded (ties: the lower rank).
TilePlan plan_tiles(const TileGrid& grid, const std::vector<std::uint64_t>& hist, double halo,
                    std::uint64_t limit, int ranks);

//! The plan's tiles, the largest (points with the halo) first; ties in tile order.
std::vector<std::size_t> largest_first(const TilePlan& plan);

//! The tiles whose box grown by the halo holds a point, found through a coarse grid (cells of
//! at least the halo) that lists per cell the tiles whose grown boxes meet it.
class HaloLookup {
 public:
  //! `box`: the cloud's bounding box (the plan's grid starts at its lower corner).
  HaloLookup(const TilePlan& plan, const Eigen::AlignedBox3d& box, double halo);
  //! hits = the home tile of p (plan.tile_of(p)) first, then, in tile order, every other tile
  //! whose box grown by the halo (in every axis: the largest gap at most the halo) holds p.
  void tiles_of(const Eigen::Vector3d& p, std::vector<std::uint32_t>& hits) const;

 private:
  const TilePlan& plan_;
  double halo_;
  TileGrid look_;
  std::vector<std::vector<std::uint32_t>> tiles_;
};

}  // namespace scanclean::detail

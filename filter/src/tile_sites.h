#pragma once
//! Internal: the kernel sites of a tiled run (tiled_filter.h). With a kernel stride s > 1 the
//! in-memory filter puts kernels at every s-th point of the whole cloud's grid order
//! (kernels.h): the order of the point index its kernels phase uses, by cell in Morton order and
//! within a cell by input index. A tiled run marks the same points, so that every tile takes
//! the whole cloud's subsample instead of its own: one pass counts the points per cell of that
//! index (each process over its records, exchanged), and the distribution pass then numbers
//! the points of each cell in record order.

#include <Eigen/Geometry>
#include <array>
#include <cstddef>
#include <cstdint>
#include <unordered_map>

#include "scanclean/filter/tiled_filter.h"

namespace scanclean::detail {

//! The grid of the point index the in-memory run's kernels phase uses over the whole cloud:
//! float coordinates relative to the box centre, anchored half a cell below their minimum, the
//! arithmetic of NeighborIndex's constructor; so a point's cell, hence its place in the whole
//! cloud's grid order, is known from the box and the cell alone.
struct SiteGrid {
  Eigen::Vector3f lo = Eigen::Vector3f::Zero();
  float inv_cell = 1;
  std::int32_t dims[3] = {1, 1, 1};
  //! The Morton code of p's cell (p relative to the box centre), the index's own cell order.
  std::uint64_t code(const Eigen::Vector3f& p) const;
};

//! The grid NeighborIndex builds with cells of `cell` over the points of `box`, taken relative
//! to `origin`.
SiteGrid site_grid(const Eigen::AlignedBox3d& box, const Eigen::Vector3d& origin, double cell);

//! The cell of the in-memory run's kernel-phase point index (scale.h, robust_filter.cpp): the
//! scale phase's first index (cell 1.6 r_est, else grid_cell_for(h0)) when it serves h, else
//! grid_cell_for(h). r_est <= 0: no such first index (not the automatic h).
double kernel_site_cell(double h, double h0, double r_est);

//! Which points are kernel sites, for one process's records.
class KernelSites {
 public:
  //! The counting pass: the points per cell of site_grid(box, box centre, cell) over the records
  //! in `range` of this process, exchanged with every process of `comm`.
  KernelSites(const TiledSource& src, std::array<std::uint64_t, 2> range, std::size_t chunk,
              const TileComm& comm, const Eigen::AlignedBox3d& box, double cell,
              std::uint64_t stride);
  //! Whether the next point of this process's records, at p, is a kernel site: called once for
  //! each point of the range, in record order.
  bool next_is_site(const Eigen::Vector3d& p);

 private:
  Eigen::Vector3d origin_;
  SiteGrid grid_;
  std::uint64_t stride_;
  //! Per occupied cell: the rank mod stride, in the whole cloud's grid order, of the first of
  //! its points that this process reads, and the points of it numbered so far.
  std::unordered_map<std::uint64_t, std::array<std::uint64_t, 2>> cells_;
};

}  // namespace scanclean::detail

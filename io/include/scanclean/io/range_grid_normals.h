#pragma once
//! \file range_grid_normals.h
//! Oriented normals of a range scan from its grid (PLY range_grid, organized PCD): what a scanner
//! that knows where it looked from gives a cloud that has no normals of its own.

#include <Eigen/Core>
#include <cstddef>
#include <vector>

#include "scanclean/core/point_cloud.h"

namespace scanclean {

struct RangeGridNormalOptions {
  //! Central differences over +-stencil grid cells along the rows and along the columns.
  int stencil = 2;
  //! A stencil point farther from the centre than max_jump x stencil x the scan's grid step (the
  //! median distance between row neighbours) lies across a depth jump: that point gets no normal.
  double max_jump = 3.0;
};

struct RangeGridNormals {
  std::vector<Eigen::Vector3f> normals;  //!< per point: unit, or zero where there is none
  std::size_t with_normal = 0;           //!< points that got one
  //! Of those, how many face the scanner once turned: n . toward > 0, or n . (viewpoint - p) > 0.
  std::size_t facing = 0;
};

//! Per point of `scan`: the unit normal of the stencil's two central differences, all turned to
//! the one side most of them face `toward` (the direction from the surface to the scanner, in the
//! scan's frame). One sign for the whole grid, not one per point, so surfaces seen at grazing
//! angles keep the orientation of their neighbours. Points at the grid's border, beside empty
//! cells or across a depth jump get a zero normal, and so does every point of a cloud without a
//! grid.
RangeGridNormals range_grid_normals(const PointCloud& scan, const Eigen::Vector3d& toward,
                                    const RangeGridNormalOptions& options = {});

//! The same for a scan taken from a point: `viewpoint` is the scanner's position in the scan's
//! frame (metres; the origin for a depth camera's organized cloud in its own frame, as PCL's
//! sensor origin), and a normal n at p faces it when n . (viewpoint - p) > 0. Still one sign for
//! the whole grid, the side most of the normals face.
RangeGridNormals range_grid_normals_from_viewpoint(const PointCloud& scan,
                                                   const Eigen::Vector3d& viewpoint,
                                                   const RangeGridNormalOptions& options = {});

}  // namespace scanclean

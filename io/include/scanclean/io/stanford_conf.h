#pragma once
//! \file stanford_conf.h
//! Stanford 3D Scanning Repository alignment files (.conf), e.g. bun.conf:
//!
//!   camera tx ty tz qx qy qz qw          (viewing camera of the original tool: ignored)
//!   bmesh bun045.ply tx ty tz qx qy qz qw (one range scan and its pose)
//!   mesh <name> tx ty tz qx qy qz qw      (a reconstruction, not a scan: ignored with a warning)
//!
//! Convention (checked against the data, see tests/io/stanford_conf_test.cpp): a scan point p
//! maps into the common frame as  R(conj(q)) * p + t = R(q)^T * p + t  with q = (qw, qx, qy, qz)
//! normalised; equivalently R(q') p + t with q' = (-qw, qx, qy, qz), the "flip the sign of qw"
//! that public scripts mention. With this, every bun.conf scan lies on bun_zipper.ply (median
//! distance ~0.06 mm per scan); with R(q) p + t, R(q)^T (p - t) or R(q) (p - t) most scans are
//! 10-200 mm off. Scan paths are relative to the .conf's folder. Units: metres.

#include <Eigen/Geometry>
#include <cstdint>
#include <filesystem>
#include <vector>

#include "scanclean/core/point_cloud.h"
#include "scanclean/io/io_types.h"

namespace scanclean {

struct ScanSession {
  std::vector<std::filesystem::path> files;  //!< resolved scan paths (conf folder / name)
  std::vector<Eigen::Isometry3d> poses;      //!< scan-to-common-frame transforms, per file
  std::vector<std::uint64_t> lines;          //!< conf line of each bmesh entry
};

//! Parses the .conf (does not open the scans). Unknown or `mesh` lines are skipped with a warning
//! (into report, if given). \throw InputError naming the line (bad numbers, zero quaternion,
//! missing fields, no bmesh line at all), IoError.
ScanSession read_conf(const std::filesystem::path& conf, ReadReport* report = nullptr);

struct ConfOptions {
  //! false (default): a scan file listed in the conf but absent is an InputError naming the conf
  //! line. true: it is skipped with a warning (the bundled bun.conf lists bun315.ply and
  //! top3.ply, which are not shipped).
  bool skip_missing = false;
  //! true (default): every scan with a range grid gives its points normals from it
  //! (range_grid_normals), turned towards the scanner, which sits on the +z side of the scan's
  //! frame (in each of bun.conf's eight scans 99.6-99.97 % of the grid's triangles face +z, and
  //! Stanford's bun_zipper.ply faces the same way there), then rotated into the common frame.
  //! Points at a grid border, beside a hole or across a depth jump, and scans without a grid,
  //! get zero normals (none); a scan whose grid normals do not face +z by at least 90 % gets a
  //! warning.
  bool scan_normals = true;
};

//! Reads every bmesh scan (read_point_cloud), gives its points normals from its range grid
//! (ConfOptions::scan_normals), brings it into the common frame and merges them into one
//! unorganized cloud (per-scan grids are dropped). Warnings of every scan are collected in
//! report. \throw InputError, IoError.
PointCloud read_and_merge_conf(const std::filesystem::path& conf, ReadReport* report = nullptr,
                               const ConfOptions& options = {});

//! The transform of a conf line's `tx ty tz qx qy qz qw` (see the convention above).
//! \throw InputError-free; the caller checks that q is not zero.
Eigen::Isometry3d conf_pose(const Eigen::Vector3d& t, const Eigen::Quaterniond& q);

}  // namespace scanclean

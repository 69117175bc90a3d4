#pragma once
//! \file organized_cloud_source.h
//! Organized point clouds (PCD with width x height > 1 row, PLY with a range_grid) as a range
//! source: one file, or a folder of them played in name order, the way a PCL grabber writes a
//! sequence (frame_20121214T142255.814212.pcd, ...). Each cloud becomes a RangeFrame whose
//! points image holds its points (NaN = no point) and whose colour image holds its colours,
//! so that replay and capture fuse, filter and colour them like depth frames.

#include <filesystem>
#include <memory>
#include <vector>

#include "scanclean/core/range_source.h"

namespace scanclean {

//! The organized clouds of a file or folder: a .pcd or .ply file alone, or a folder's .pcd and
//! .ply files in natural name order. \throw InputError when there are none.
std::vector<std::filesystem::path> list_organized_clouds(const std::filesystem::path& path);

//! A finite source over organized clouds (list_organized_clouds). open() reads the first cloud
//! and fits the pinhole intrinsics its points follow (u = fx x / z + cx, v = fy y / z + cy, least
//! squares over every point; \throw InputError naming the file when the cloud is not organized,
//! or its points are not a pinhole range image within 0.5 px RMS). next() reads one cloud per
//! call (\throw InputError for a cloud of another grid size) and returns kEndOfStream after the
//! last. Frame index = position; device_ts_us from PCL grabber or TUM names when every name has
//! one and they increase, else index x 1/30 s. info().kind "organized-clouds".
std::unique_ptr<RangeSource> make_organized_cloud_source(const std::filesystem::path& path);

}  // namespace scanclean

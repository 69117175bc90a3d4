#pragma once
//! \file xyz.h
//! Plain-text point lists (.xyz, .txt): one point per line, whitespace-separated
//! `x y z` or `x y z nx ny nz`; `#` starts a comment (whole line or the rest of a line); blank
//! lines are ignored. Every data line must have the same number of values as the first one.
//! Points with a non-finite coordinate are dropped and counted (ReadReport::dropped_invalid).
//! The format carries positions and normals only, and no unit (metres by convention here).

#include <filesystem>

#include "scanclean/core/point_cloud.h"
#include "scanclean/io/io_types.h"

namespace scanclean {

//! \throw InputError (a line with the wrong number of values or a non-number, naming the line),
//! IoError.
PointCloud read_xyz(const std::filesystem::path& path, ReadReport* report = nullptr);

//! Writes `x y z [nx ny nz]` lines (shortest round-trip decimal text), atomically. Only positions
//! and normals are written. \throw IoError.
void write_xyz(const std::filesystem::path& path, const PointCloud& cloud);

}  // namespace scanclean

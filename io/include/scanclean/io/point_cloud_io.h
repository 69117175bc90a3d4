#pragma once
//! \file point_cloud_io.h
//! Point-cloud files, dispatched by extension (case-insensitive). Every reader treats its input
//! as untrusted: malformed data gives an InputError "<file>: <line N | byte N>: <what was
//! expected>", never a crash or an allocation the file size cannot justify; nothing is dropped
//! silently (ReadReport lists skipped header lines/fields/elements and dropped points).
//! Every writer is atomic (core/atomic_file.h): a failed write leaves no partial file.
//!
//! | ext        | format  | read                                        | write |
//! |------------|---------|---------------------------------------------|-----------------------------|
//! | .ply       | PLY 1.0 | ascii, binary_little_endian,                | binary_little_endian | |
//! |         | binary_big_endian; any vertex property      | (default) or ascii; every   | | | |
//! types; range_grid -> OrganizedGrid          | array + attributes + grid   | | .pcd       | PCD
//! 0.7 | ascii, binary, binary_compressed (LZF);     | ascii, binary,              | |            |
//! (.6 .5) | organized (HEIGHT>1) -> OrganizedGrid       | binary_compressed (default) | | .xyz
//! .txt  | text    | x y z [nx ny nz] per line, # comments       | x y z [nx ny nz]            | |
//! .conf      | Stanford| read_and_merge_conf (stanford_conf.h)        | - |
//!
//! Array mapping (details in ply.h / pcd.h / xyz.h): positions (x y z), normals (nx ny nz /
//! normal_x ...), confidences (confidence), intensities (intensity), colours (red green blue
//! [alpha] / packed rgb(a)), every other scalar per-point field -> a named Attribute with its
//! type. Non-finite points are dropped and counted in ReadReport::dropped_invalid (their grid
//! cells become empty). Units: none in the files; metres by convention (the bundled data are
//! in metres).

#include <filesystem>
#include <string>

#include "scanclean/core/point_cloud.h"
#include "scanclean/io/io_types.h"
#include "scanclean/io/pcd.h"
#include "scanclean/io/ply.h"
#include "scanclean/io/stanford_conf.h"
#include "scanclean/io/xyz.h"

namespace scanclean {

//! "ply", "pcd" or "xyz" for a supported extension; "" otherwise.
std::string point_cloud_format(const std::filesystem::path& path);

//! Reads .ply, .pcd, .xyz or .txt. \throw InputError (unsupported extension, malformed file),
//! IoError (cannot open/read).
//! `xyz` applies to .xyz/.txt files only. A folder is reported as a folder.
PointCloud read_point_cloud(const std::filesystem::path& path, ReadReport* report = nullptr,
                            const XyzOptions& xyz = {});

//! Writes by OUT's extension, atomically. \throw OptionError (unsupported extension or option),
//! IoError.
void write_point_cloud(const std::filesystem::path& path, const PointCloud& cloud,
                       const WriteOptions& options = {});

}  // namespace scanclean

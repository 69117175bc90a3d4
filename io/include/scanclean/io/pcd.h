#pragma once
//! \file pcd.h
//! PCD (Point Cloud Library) point clouds.
//!
//! Reading: header VERSION 0.7 (0.6 and 0.5 headers accepted), FIELDS SIZE TYPE COUNT WIDTH
//! HEIGHT VIEWPOINT POINTS DATA; encodings ascii, binary (array of structs) and
//! binary_compressed (uint32 compressed size, uint32 uncompressed size, LZF payload holding each
//! field contiguously). Fields: x y z (required); normal_x normal_y normal_z; rgb / rgba (packed
//! 0x00RRGGBB / 0xAARRGGBB, stored as float or uint32) -> colours (rgb: alpha 255); intensity;
//! every other COUNT 1 field (e.g. curvature) -> an Attribute (I1/I2/I4 -> kInt32, U1 -> kUInt8,
//! U2/U4 -> kUInt32, F4 -> kFloat32, F8/I8/U8 -> kFloat64); COUNT > 1 fields (histograms such as
//! FPFH) and padding fields "_" are skipped with a warning. The VIEWPOINT is not applied (a
//! warning says so when it is not the identity).
//! Organized clouds (HEIGHT > 1) keep their grid (rows = HEIGHT, cols = WIDTH); points with a
//! non-finite x, y or z (NaN marks missing pixels) are dropped, their cells become -1, and the
//! count goes to ReadReport::dropped_invalid (unorganized clouds: dropped and counted the same).
//! Malformed files give an InputError naming the file, the line or byte offset and what was
//! expected; sizes declared by the header are checked against the file before allocating.
//!
//! Writing (atomic): fields x y z (F4, or F8 when float would lose precision, see ply.h),
//! normal_x normal_y normal_z, rgba (U4), intensity, confidence and every Attribute with its type.
//! An organized cloud whose grid holds each point exactly once is written organized (WIDTH =
//! cols, HEIGHT = rows, points in grid order, NaN x y z in empty cells); otherwise unorganized.

#include <filesystem>
#include <string>

#include "scanclean/core/point_cloud.h"
#include "scanclean/io/io_types.h"

namespace scanclean {

//! \throw InputError (malformed file), IoError (cannot read).
PointCloud read_pcd(const std::filesystem::path& path, ReadReport* report = nullptr);

//! encoding: "ascii", "binary" or "binary_compressed". The `#` header comments name the scanclean
//! version and, when given, the provenance text (WriteOptions::provenance). \throw OptionError
//! (unknown encoding), IoError.
void write_pcd(const std::filesystem::path& path, const PointCloud& cloud,
               const std::string& encoding = "binary_compressed",
               const std::string& provenance = {});

}  // namespace scanclean

#pragma once
//! \file ply.h
//! PLY (Stanford polygon file format) point clouds.
//!
//! Reading: ascii, binary_little_endian and binary_big_endian; vertex properties of any PLY type
//! (char uchar short ushort int uint float double and the int8 ... float64 aliases) in any
//! order. x y z are required; nx ny nz, confidence, intensity and red green blue [alpha] (or
//! diffuse_red ...) fill the PointCloud arrays; every other scalar vertex property becomes an
//! Attribute (char/short/int -> kInt32, uchar -> kUInt8, ushort/uint -> kUInt32, float ->
//! kFloat32, double -> kFloat64). List properties of the vertex element are skipped with a
//! warning. A `range_grid` element (a list of vertex indices per cell, Stanford scans) becomes
//! the cloud's OrganizedGrid, sized by `obj_info num_rows` / `obj_info num_cols`; other elements
//! (faces, ...) are skipped. `comment` and `obj_info` header lines are accepted; unknown header
//! lines (e.g. the `bye` lines of the Stanford dragon scans) are skipped with a warning.
//!
//! Non-finite vertices (NaN or infinite x, y or z) are dropped: counted in
//! ReadReport::dropped_invalid and reported by a warning; their grid cells become empty.
//! Every structural problem (truncated data, a header that declares more data than the file
//! holds, unknown types, values out of range for their type, ...) is an InputError naming the
//! file, the line (ascii) or byte offset (binary) and what was expected. The reader checks
//! declared sizes against the file size before allocating.
//!
//! Writing (atomic): binary little-endian or ascii. Positions are written as float when every
//! coordinate survives the conversion to float within 1e-6 of the bounding-box diagonal (the
//! usual case for scanner data), else as double. Then nx ny nz (float), confidence (float),
//! intensity (float), red green blue alpha (uchar), every Attribute with its type (kUInt8 uchar,
//! kInt32 int, kUInt32 uint, kFloat32 float, kFloat64 double), and, for organized clouds, a
//! range_grid element plus obj_info num_cols / num_rows. PLY carries no unit (metres by
//! convention here). The header comments name the scanclean version and, when given, the
//! provenance text (WriteOptions::provenance, e.g. the command line).

#include <filesystem>

#include "scanclean/core/point_cloud.h"
#include "scanclean/io/io_types.h"

namespace scanclean {

//! Reads a PLY point cloud. \throw InputError (malformed file), IoError (cannot read).
PointCloud read_ply(const std::filesystem::path& path, ReadReport* report = nullptr);

//! Writes a PLY point cloud atomically. \throw IoError; std::logic_error if the cloud is
//! inconsistent (PointCloud::check_consistent).
void write_ply(const std::filesystem::path& path, const PointCloud& cloud,
               PlyEncoding encoding = PlyEncoding::kBinaryLittleEndian,
               const std::string& provenance = {});

}  // namespace scanclean

#pragma once
//! \file xyz.h
//! Plain-text point lists (.xyz, .txt): one point per line, whitespace- (or comma-) separated
//! numbers; `#` starts a comment (whole line or the rest of a line); blank lines are ignored.
//! Every data line must have the same number of values as the first one. Points with a
//! non-finite coordinate are dropped and counted (ReadReport::dropped_invalid).
//!
//! Columns. Names: x y z (position), nx ny nz (normal), r g b (colour: 0-255 integers, or 0-1
//! when every colour value of the file is within [0, 1]), i (intensity), '-' (skipped). They are
//! taken, in this order of precedence, from XyzOptions::columns (`--xyz-columns x,y,z,r,g,b`),
//! from a header line of names (CloudCompare's "//X Y Z R G B Nx Ny Nz" or a line of names
//! only), or guessed from the number of values and the values themselves:
//!   3: x y z; 4: x y z i; 6: x y z nx ny nz when every 4-6 triple has unit length (or is zero),
//!   else x y z r g b when every one is an integer triple in [0, 255] or a triple within [0, 1]; 7:
//!   x y z r g b i (CloudCompare's colour and scalar field); 9: x y z r g b nx ny nz or x y z nx ny
//!   nz r g b, by which triple has unit length.
//! A count or a content the guess cannot settle is an InputError asking for the columns. The
//! ReadReport's fields say what was read (x y z r g b ...) and its encoding how ("ascii, columns
//! guessed from 6 values per line", "... from the header line", "... as given"). The format carries
//! no unit (metres by convention here).

#include <filesystem>
#include <string>
#include <vector>

#include "scanclean/core/point_cloud.h"
#include "scanclean/io/io_types.h"

namespace scanclean {

struct XyzOptions {
  //! Column names (x y z nx ny nz r g b i -); empty = from a header line or guessed.
  std::vector<std::string> columns;
};

//! Parses "x,y,z,r,g,b" (commas or spaces). \throw OptionError naming --xyz-columns (unknown
//! name, a name twice, x y z missing, normals or colours incomplete).
std::vector<std::string> parse_xyz_columns(const std::string& text);

//! \throw InputError (a line with the wrong number of values or a non-number, naming the line;
//! no points; columns that cannot be guessed), IoError.
PointCloud read_xyz(const std::filesystem::path& path, ReadReport* report = nullptr,
                    const XyzOptions& options = {});

//! Writes `x y z [nx ny nz]` lines (shortest round-trip decimal text), atomically. Only positions
//! and normals are written. \throw IoError.
void write_xyz(const std::filesystem::path& path, const PointCloud& cloud);

}  // namespace scanclean

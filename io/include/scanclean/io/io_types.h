#pragma once
//! \file io_types.h
//! Options and reports shared by every point-cloud reader and writer.

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace scanclean {

//! What a reader noticed besides the data. Readers never lose data silently: every skipped
//! header line, ignored element/field and dropped point is listed here.
struct ReadReport {
  std::vector<std::string> warnings;  //!< "<file>: <place>: <what>" messages
  std::size_t dropped_invalid = 0;    //!< points dropped because x, y or z was NaN or infinite
  // Description of the file (filled by every reader; used by `scanclean info`).
  std::string format;                 //!< "ply", "pcd", "xyz"
  std::string encoding;               //!< "ascii", "binary_little_endian", "binary_compressed", ...
  std::vector<std::string> fields;    //!< per-point fields in file order, e.g. "x:float32"
  std::uint64_t declared_points = 0;  //!< points declared by the file (before dropping)
};

enum class PlyEncoding { kBinaryLittleEndian, kAscii };

struct WriteOptions {
  PlyEncoding ply_encoding = PlyEncoding::kBinaryLittleEndian;
  std::string pcd_encoding = "binary_compressed";  //!< ascii | binary | binary_compressed
  //! Provenance written as a header comment of PLY and PCD files (after the scanclean version),
  //! e.g. the command line; control characters become spaces; empty = none.
  std::string provenance;
};

//! Throws OptionError naming the option when pcd_encoding is not one of the three values.
void validate(const WriteOptions& options);

}  // namespace scanclean

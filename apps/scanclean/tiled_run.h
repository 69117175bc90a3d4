#pragma once
// The tiled, out-of-core filter run on files, shared by `scanclean filter` (one process) and
// `scanclean-mpi` (many): streams a binary PLY/PCD in, writes the output PLY (and the outliers
// PLY) tile by tile, and makes them visible together, atomically, at the end. With several
// processes, each writes its tiles' results to the scratch folder; at the end process 0
// reserves room in the outputs for all of them, each process writes its own in place at their
// offsets in tile order, and process 0 commits the outputs: the same bytes for any number of
// processes, and no result travels through one process.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>

#include "scanclean/filter/tiled_filter.h"

namespace scanclean::app {

//! Parses a memory size: bytes, or a number with K, M, G or T (binary units, "2G", "1.5G",
//! "512M"). \throw OptionError naming `option`.
std::size_t parse_memory_size(const std::string& option, const std::string& text);

//! The default budget: 2 GiB, or half the machine's memory when that is less.
std::size_t default_memory_budget();

struct TiledRunRequest {
  std::filesystem::path input, output, outliers;  //!< outliers: empty = not written
  FilterOptions filter;
  TiledOptions tiled;  //!< scratch: empty = a private folder beside the output
  std::string provenance;
  TileComm comm;
};

struct TiledRunResult {
  TiledStats stats;
  std::uint64_t records = 0;          //!< records in the input file
  std::uint64_t dropped_invalid = 0;  //!< of them, dropped by the reader (x, y or z not finite)
  bool written = false;               //!< false: collapsed result, nothing written
  //! Seconds this process spent writing the outputs after the tiles: its tiles' results (with
  //! several processes, in place) and, on process 0, the headers and the commit.
  double seconds_writing = 0;
};

//! Runs it. \throw OptionError, InputError, IoError.
TiledRunResult run_tiled(const TiledRunRequest& request);

}  // namespace scanclean::app

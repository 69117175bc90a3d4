#pragma once
//! Internal: the scratch files of a tiled run (tiled_filter.h). Each process writes, per tile,
//! one file of fixed-size records (the points of its record range that the tile holds, halo
//! included); the process that filters the tile reads every process's file of it and removes it.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "scanclean/core/point_cloud.h"

namespace scanclean::detail {

//! Record numbers in the scratch files carry the kernel-site mark in their top bit.
constexpr std::uint64_t kSiteBit = std::uint64_t{1} << 63;

//! What a scratch record holds: the record number (8 bytes), the position (3 doubles), then the
//! arrays the input has, in this order: normal (3 floats), confidence, intensity (floats),
//! colour (4 bytes), and each attribute as a double.
struct ScratchColumns {
  bool normals = false, confidences = false, intensities = false, colors = false;
  //! The input's attributes (TiledSource::attributes), each value a double in the record.
  std::vector<std::pair<std::string, AttributeType>> attributes;
  //! Bytes per record.
  std::size_t bytes() const {
    return 8 + 24 + (normals ? 12 : 0) + (confidences ? 4 : 0) + (intensities ? 4 : 0) +
           (colors ? 4 : 0) + 8 * attributes.size();
  }
};

//! Checks that c carries every array `cols` names, one value a point, and exactly cols'
//! attributes. \throw std::logic_error naming the array: the source's chunks disagree (a
//! TiledSource must fill the same arrays in every chunk).
void check_columns(const PointCloud& c, const ScratchColumns& cols);

//! Appends point i of c to buf as one record numbered `record`. c holds every array `cols`
//! names, and exactly cols.attributes' attributes, in that order.
void put_point(std::string& buf, const PointCloud& c, std::size_t i, std::uint64_t record,
               const ScratchColumns& cols);

//! Appends the records of `file` to c and their numbers to `records` (nothing when the file does
//! not exist: no point of that process's range fell into the tile). \throw IoError naming the
//! file when its size is not a whole number of records.
void read_points(const std::filesystem::path& file, const ScratchColumns& cols, PointCloud& c,
                 std::vector<std::uint64_t>& records);

//! The scratch file of `tile` written by process `rank`, in `folder`.
std::filesystem::path scratch_file(const std::filesystem::path& folder, std::size_t tile, int rank);

//! One process's scratch files: records buffered per tile and appended to the tile's file once
//! its buffer holds `flush_at` bytes (the file is created at the first flush).
class ScratchWriter {
 public:
  ScratchWriter(std::filesystem::path folder, std::size_t tiles, int rank, std::size_t flush_at);
  //! Point i of c, as record `record`, into the file of `tile`. \throw IoError naming the file.
  void put(std::size_t tile, const PointCloud& c, std::size_t i, std::uint64_t record,
           const ScratchColumns& cols);
  //! Writes what is buffered and closes every file. \throw IoError naming the file.
  void finish();

 private:
  void flush(std::size_t tile);
  std::filesystem::path folder_;
  int rank_;
  std::size_t flush_at_;
  std::vector<std::string> buf_;
  std::vector<std::unique_ptr<std::ofstream>> files_;
};

//! Removes the scratch files when the run ends by an exception (a run that ends normally has
//! removed each as its tile read it). With one process, its own. With several, every process's:
//! the others wait for this one in their next exchange, so the run is over for all of them, and
//! a process stopped there (MPI_Abort) cannot clean up after itself.
class ScratchCleanup {
 public:
  ScratchCleanup(std::filesystem::path folder, std::size_t tiles, int ranks);
  ScratchCleanup(const ScratchCleanup&) = delete;
  ScratchCleanup& operator=(const ScratchCleanup&) = delete;
  ~ScratchCleanup();

 private:
  std::filesystem::path folder_;
  std::size_t tiles_;
  int ranks_;
  int uncaught_;
};

}  // namespace scanclean::detail

#pragma once
//! \file ply_stream_writer.h
//! A binary little-endian PLY written piece by piece, for outputs larger than memory: the points
//! are appended as they are produced (e.g. tile by tile), and the file becomes visible only at
//! finish(), atomically (core/atomic_file.h; inside an AtomicCommitGroup like every writer). The
//! header is written first with a reserved width, and rewritten in place with the final vertex
//! count at finish(). Every piece must have the same arrays and attributes (PlyLayout).

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "scanclean/core/point_cloud.h"

namespace scanclean {

class AtomicFile;

//! The columns of a streamed PLY: which optional arrays and which attributes, in write_ply's
//! order (x y z, nx ny nz, confidence, intensity, red green blue alpha, attributes).
struct PlyLayout {
  bool double_positions = false;  //!< x y z as double (else float)
  bool normals = false, confidences = false, intensities = false, colors = false;
  std::vector<std::pair<std::string, AttributeType>> attributes;
  bool operator==(const PlyLayout&) const = default;
};

//! The layout of `cloud`'s arrays and attributes.
PlyLayout ply_layout_of(const PointCloud& cloud, bool double_positions);

//! The binary little-endian vertex records of `cloud` in `layout`. \throw std::logic_error if
//! the cloud's arrays or attributes do not match the layout.
std::string encode_ply_vertices(const PointCloud& cloud, const PlyLayout& layout);

class PlyStreamWriter {
 public:
  //! Creates the temporary file beside `path` and writes the provisional header.
  //! \throw IoError.
  PlyStreamWriter(const std::filesystem::path& path, PlyLayout layout,
                  const std::string& provenance = {});
  ~PlyStreamWriter();  //!< without finish(), the target is left untouched
  PlyStreamWriter(const PlyStreamWriter&) = delete;
  PlyStreamWriter& operator=(const PlyStreamWriter&) = delete;

  //! Appends the points of `cloud`. \throw std::logic_error (layout), IoError.
  void append(const PointCloud& cloud);
  //! Appends `points` vertex records already encoded by encode_ply_vertices(). \throw IoError.
  void append_encoded(const std::string& records, std::uint64_t points);
  //! Leaves room at the end for `points` vertex records of `bytes` bytes, which other processes
  //! write in place (write_at() on temporary()) before finish(); returns the room's offset in
  //! the file. The points count in the header. \throw IoError.
  std::uint64_t reserve(std::uint64_t bytes, std::uint64_t points);
  //! The temporary file the points go to until finish() commits it.
  const std::filesystem::path& temporary() const;
  std::uint64_t points() const { return points_; }
  const PlyLayout& layout() const { return layout_; }
  //! Rewrites the header with the vertex count and commits the file. \throw IoError.
  void finish();

 private:
  std::string header(std::uint64_t count) const;
  std::filesystem::path path_;
  PlyLayout layout_;
  std::string provenance_;
  std::size_t header_size_ = 0;
  std::uint64_t points_ = 0;
  std::uint64_t end_ = 0;  // bytes in the file, the header included
  std::unique_ptr<AtomicFile> file_;
};

//! Writes `bytes` at `offset` of the existing `file` (room another process reserved with
//! PlyStreamWriter::reserve()) and syncs them to the disk. \throw IoError naming the file.
void write_at(const std::filesystem::path& file, std::uint64_t offset, const std::string& bytes);

}  // namespace scanclean

#pragma once
//! \file point_stream.h
//! Streaming reads of binary point-cloud files by ranges of records, for clouds larger than
//! memory: binary PLY (either byte order) and binary PCD. Only the header is parsed when the
//! stream is opened; each read() takes the bytes of the requested records with pread() (chunked,
//! never the whole file), so that many threads or processes can read disjoint ranges of one file
//! at the same time.
//!
//! Record i is the i-th vertex (PLY) or point (PCD) of the file. The fields map to the cloud as
//! the whole-file readers map them (read_ply, read_pcd): x y z (required, any numeric type);
//! normals (nx ny nz, else normal_x normal_y normal_z); confidence; intensity; colours (PLY red
//! green blue [alpha], else diffuse_red ..., integers 0-255 or floats in [0, 1]; PCD rgb / rgba
//! packed); every other scalar field (PCD: COUNT 1, not "_") becomes an Attribute of the same
//! name and type, in file order (attributes()). The first of two fields with one name is used.
//! Records with a non-finite x, y or z are dropped like the whole-file readers do; read()
//! returns the record index of every point it keeps.
//!
//! Not streamable (an InputError says so and names the whole-file reader to use instead): ASCII
//! PLY or PCD, binary_compressed PCD, list properties in the PLY vertex element, or a PLY element
//! with list properties before the vertices. A file shorter than its header declares is an
//! InputError naming the file and the byte offset when it is opened.

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "scanclean/core/point_cloud.h"

namespace scanclean {

class PointStream {
 public:
  //! Opens a .ply or .pcd file and parses its header. \throw InputError (not streamable,
  //! malformed or truncated: names the file and the place), IoError (cannot open).
  static std::unique_ptr<PointStream> open(const std::filesystem::path& path);
  //! Whether `path` is a binary PLY / binary PCD that open() accepts (false for any other file,
  //! including unreadable ones); reads the header only.
  static bool streamable(const std::filesystem::path& path);
  ~PointStream();
  PointStream(const PointStream&) = delete;
  PointStream& operator=(const PointStream&) = delete;

  const std::filesystem::path& path() const { return path_; }
  std::uint64_t size() const { return records_; }         //!< records in the file
  std::uint64_t record_bytes() const { return stride_; }  //!< bytes per record
  std::uint64_t data_offset() const { return data_; }     //!< byte offset of record 0
  std::string format() const { return pcd_ ? "pcd" : "ply"; }
  bool has_normals() const { return normals_; }
  bool has_confidences() const { return confidence_ >= 0; }
  bool has_intensities() const { return intensity_ >= 0; }
  bool has_colors() const { return colors_; }
  //! The attributes every read() fills (name, type), in file order: the fields above take none.
  const std::vector<std::pair<std::string, AttributeType>>& attributes() const {
    return attribute_types_;
  }

  //! Reads records [first, first + count) (clipped to size()) into `out` (replaced), dropping
  //! non-finite points; `records` (optional) receives the record index of each point kept.
  //! Thread-safe (pread). \throw IoError (read failed), InputError (a confidence outside [0, 1]
  //! is not checked here; the filter does).
  void read(std::uint64_t first, std::uint64_t count, PointCloud& out,
            std::vector<std::uint64_t>* records = nullptr) const;

  //! Calls f(cloud, records) for consecutive chunks of at most `chunk` records of
  //! [first, first + count), in record order. Memory: one chunk.
  void for_each_chunk(
      std::uint64_t first, std::uint64_t count, std::size_t chunk,
      const std::function<void(const PointCloud&, const std::vector<std::uint64_t>&)>& f) const;

  //! The records [first, last) that process `rank` of `ranks` reads: an even split.
  static std::array<std::uint64_t, 2> split(std::uint64_t records, int rank, int ranks);

 private:
  PointStream() = default;
  struct Field {
    int type = -1;  // internal type code, -1 = absent
    std::uint32_t offset = 0;
  };
  std::filesystem::path path_;
  int fd_ = -1;
  bool pcd_ = false;
  bool big_endian_ = false;
  std::uint64_t records_ = 0;
  std::uint64_t stride_ = 0;
  std::uint64_t data_ = 0;
  std::array<Field, 3> xyz_{};
  std::array<Field, 3> n_{};
  bool normals_ = false;
  Field conf_{}, inten_{};
  int confidence_ = -1, intensity_ = -1;
  std::array<Field, 4> rgba_{};  // PLY: red green blue [alpha]; PCD: packed in rgba_[0]
  bool colors_ = false;
  bool packed_colour_ = false;  // PCD rgb / rgba packed in rgba_[0]
  bool packed_alpha_ = false;   // PCD rgba (else rgb: alpha 255)
  std::vector<Field> attribute_fields_;
  std::vector<std::pair<std::string, AttributeType>> attribute_types_;
  friend struct PointStreamParser;
};

}  // namespace scanclean

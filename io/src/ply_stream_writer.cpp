// A binary PLY written piece by piece and committed atomically (ply_stream_writer.h).
#include "scanclean/io/ply_stream_writer.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "header_comment.h"
#include "ply_encode.h"
#include "scanclean/core/atomic_file.h"
#include "scanclean/core/errors.h"

namespace scanclean {
namespace {

using io_detail::put_le;
using io_detail::put_ply_binary;

// Room for the final vertex count in the provisional header (20 digits hold any 64-bit count).
constexpr std::size_t kCountWidth = 20;

}  // namespace

PlyLayout ply_layout_of(const PointCloud& cloud, bool double_positions) {
  PlyLayout l;
  l.double_positions = double_positions;
  l.normals = cloud.has_normals();
  l.confidences = cloud.has_confidences();
  l.intensities = cloud.has_intensities();
  l.colors = cloud.has_colors();
  for (const auto& a : cloud.attributes) l.attributes.emplace_back(a.name, a.type);
  return l;
}

std::string encode_ply_vertices(const PointCloud& cloud, const PlyLayout& l) {
  const std::size_t n = cloud.size();
  if (n == 0) return {};
  PlyLayout have = ply_layout_of(cloud, l.double_positions);
  if (!(have == l))
    throw std::logic_error(
        "encode_ply_vertices: the cloud's arrays or attributes differ from the "
        "layout of the file");
  cloud.check_consistent();
  std::string buf;
  buf.reserve(n * 48);
  for (std::size_t i = 0; i < n; ++i) {
    for (int k = 0; k < 3; ++k) {
      if (l.double_positions)
        put_le(buf, cloud.positions[i][k]);
      else
        put_le(buf, static_cast<float>(cloud.positions[i][k]));
    }
    if (l.normals)
      for (int k = 0; k < 3; ++k) put_le(buf, cloud.normals[i][k]);
    if (l.confidences) put_le(buf, cloud.confidences[i]);
    if (l.intensities) put_le(buf, cloud.intensities[i]);
    if (l.colors) buf.append(reinterpret_cast<const char*>(cloud.colors[i].data()), 4);
    for (const auto& a : cloud.attributes) put_ply_binary(buf, a.type, a.values[i]);
  }
  return buf;
}

PlyStreamWriter::PlyStreamWriter(const std::filesystem::path& path, PlyLayout layout,
                                 const std::string& provenance)
    : path_(path), layout_(std::move(layout)), provenance_(provenance) {
  file_ = std::make_unique<AtomicFile>(path_, true);
  const std::string h = header(0);
  header_size_ = h.size();
  end_ = h.size();
  file_->stream().write(h.data(), static_cast<std::streamsize>(h.size()));
  if (!file_->stream()) throw IoError(path_.string() + ": cannot write the header");
}

PlyStreamWriter::~PlyStreamWriter() = default;

std::string PlyStreamWriter::header(std::uint64_t count) const {
  std::string h = "ply\nformat binary_little_endian 1.0\n";
  h += "comment written by scanclean " SCANCLEAN_VERSION " (units: metres)\n";
  if (!provenance_.empty()) h += "comment " + io_detail::header_comment_text(provenance_) + "\n";
  // The count, then a comment that pads the header to the same size for any count.
  const std::string digits = std::to_string(count);
  h += "element vertex " + digits + "\n";
  h += "comment " + std::string(kCountWidth - digits.size(), ' ') + "\n";
  const char* pos = layout_.double_positions ? "double" : "float";
  for (const char* a : {"x", "y", "z"}) h += std::string("property ") + pos + " " + a + "\n";
  if (layout_.normals)
    for (const char* a : {"nx", "ny", "nz"}) h += std::string("property float ") + a + "\n";
  if (layout_.confidences) h += "property float confidence\n";
  if (layout_.intensities) h += "property float intensity\n";
  if (layout_.colors)
    for (const char* a : {"red", "green", "blue", "alpha"})
      h += std::string("property uchar ") + a + "\n";
  for (const auto& [name, type] : layout_.attributes)
    h += std::string("property ") + io_detail::ply_type_name(type) + " " +
         io_detail::sanitize_ply_name(name) + "\n";
  h += "end_header\n";
  return h;
}

void PlyStreamWriter::append(const PointCloud& cloud) {
  append_encoded(encode_ply_vertices(cloud, layout_), cloud.size());
}

void PlyStreamWriter::append_encoded(const std::string& records, std::uint64_t points) {
  if (!file_) throw std::logic_error("PlyStreamWriter: append after finish");
  file_->stream().write(records.data(), static_cast<std::streamsize>(records.size()));
  if (!file_->stream()) throw IoError(path_.string() + ": write failed (disk full?)");
  points_ += points;
  end_ += records.size();
}

std::uint64_t PlyStreamWriter::reserve(std::uint64_t bytes, std::uint64_t points) {
  if (!file_) throw std::logic_error("PlyStreamWriter: reserve after finish");
  std::ostream& os = file_->stream();
  os.flush();
  if (!os) throw IoError(path_.string() + ": write failed (disk full?)");
  const std::uint64_t at = end_;
  std::error_code ec;
  std::filesystem::resize_file(file_->temporary(), at + bytes, ec);
  if (ec)
    throw IoError(path_.string() + ": cannot make room for " + std::to_string(bytes) +
                  " bytes of points: " + ec.message());
  os.seekp(static_cast<std::streamoff>(at + bytes));
  if (!os) throw IoError(path_.string() + ": cannot make room for the points");
  end_ = at + bytes;
  points_ += points;
  return at;
}

const std::filesystem::path& PlyStreamWriter::temporary() const {
  if (!file_) throw std::logic_error("PlyStreamWriter: temporary() after finish");
  return file_->temporary();
}

void write_at(const std::filesystem::path& file, std::uint64_t offset, const std::string& bytes) {
  const int fd = ::open(file.c_str(), O_WRONLY | O_CLOEXEC);
  if (fd < 0)
    throw IoError(file.string() +
                  ": cannot open to write points in place: " + std::strerror(errno));
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n =
        ::pwrite(fd, bytes.data() + done, bytes.size() - done, static_cast<off_t>(offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const std::string why = n < 0 ? std::strerror(errno) : "nothing written";
      ::close(fd);
      throw IoError(file.string() + ": write failed at byte " + std::to_string(offset + done) +
                    " (disk full?): " + why);
    }
    done += static_cast<std::size_t>(n);
  }
  const bool synced = ::fsync(fd) == 0;
  const std::string why = synced ? std::string() : std::strerror(errno);
  if (::close(fd) != 0 || !synced)
    throw IoError(file.string() + ": cannot sync the points written in place: " + why);
}

void PlyStreamWriter::finish() {
  if (!file_) throw std::logic_error("PlyStreamWriter: finish twice");
  const std::string h = header(points_);
  if (h.size() != header_size_) throw std::logic_error("PlyStreamWriter: header size changed");
  std::ostream& os = file_->stream();
  os.seekp(0);
  os.write(h.data(), static_cast<std::streamsize>(h.size()));
  os.seekp(0, std::ios::end);
  if (!os) throw IoError(path_.string() + ": cannot rewrite the header");
  file_->commit();
  file_.reset();
}

}  // namespace scanclean

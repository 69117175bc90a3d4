#include "tile_scratch.h"

#include <algorithm>
#include <array>
#include <cstdio>
#include <cstring>
#include <exception>
#include <iterator>
#include <stdexcept>
#include <system_error>

#include "scanclean/core/errors.h"

namespace scanclean::detail {

void check_columns(const PointCloud& c, const ScratchColumns& cols) {
  auto require = [&](bool wanted, std::size_t have, const char* what) {
    if (wanted && have != c.size())
      throw std::logic_error(std::string("tiled filter: read() gave a chunk without the ") + what +
                             " that other records carry");
  };
  require(cols.normals, c.normals.size(), "normals");
  require(cols.confidences, c.confidences.size(), "confidences");
  require(cols.intensities, c.intensities.size(), "intensities");
  require(cols.colors, c.colors.size(), "colours");
  if (c.attributes.size() != cols.attributes.size())
    throw std::logic_error("tiled filter: read() gave other attributes than announced");
  for (const Attribute& a : c.attributes) require(true, a.values.size(), "attribute values");
}

void put_point(std::string& buf, const PointCloud& c, std::size_t i, std::uint64_t record,
               const ScratchColumns& cols) {
  auto put = [&](const void* p, std::size_t n) { buf.append(static_cast<const char*>(p), n); };
  put(&record, 8);
  put(c.positions[i].data(), 24);
  if (cols.normals) put(c.normals[i].data(), 12);
  if (cols.confidences) put(&c.confidences[i], 4);
  if (cols.intensities) put(&c.intensities[i], 4);
  if (cols.colors) put(c.colors[i].data(), 4);
  for (const Attribute& a : c.attributes) put(&a.values[i], 8);
}

void read_points(const std::filesystem::path& file, const ScratchColumns& cols, PointCloud& c,
                 std::vector<std::uint64_t>& records) {
  std::ifstream in(file, std::ios::binary);
  if (!in) return;  // no point of this rank's range fell into the tile
  const std::string bytes((std::istreambuf_iterator<char>(in)), {});
  const std::size_t n = bytes.size() / cols.bytes();
  if (n * cols.bytes() != bytes.size())
    throw IoError(file.string() + ": scratch file of a tile has a partial record");
  const char* p = bytes.data();
  if (c.attributes.empty())
    for (const auto& [name, type] : cols.attributes) c.attributes.push_back({name, type, {}});
  for (std::size_t i = 0; i < n; ++i) {
    std::uint64_t rec;
    std::memcpy(&rec, p, 8);
    records.push_back(rec);
    Eigen::Vector3d x;
    std::memcpy(x.data(), p + 8, 24);
    c.positions.push_back(x);
    p += 32;
    if (cols.normals) {
      Eigen::Vector3f v;
      std::memcpy(v.data(), p, 12);
      c.normals.push_back(v);
      p += 12;
    }
    auto f32 = [&](std::vector<float>& v) {
      float f;
      std::memcpy(&f, p, 4);
      v.push_back(f);
      p += 4;
    };
    if (cols.confidences) f32(c.confidences);
    if (cols.intensities) f32(c.intensities);
    if (cols.colors) {
      std::array<std::uint8_t, 4> col;
      std::memcpy(col.data(), p, 4);
      c.colors.push_back(col);
      p += 4;
    }
    for (Attribute& a : c.attributes) {
      double v;
      std::memcpy(&v, p, 8);
      a.values.push_back(v);
      p += 8;
    }
  }
}

std::filesystem::path scratch_file(const std::filesystem::path& folder, std::size_t tile,
                                   int rank) {
  char name[64];
  std::snprintf(name, sizeof name, "tile%06zu.r%04d.pts", tile, rank);
  return folder / name;
}

ScratchWriter::ScratchWriter(std::filesystem::path folder, std::size_t tiles, int rank,
                             std::size_t flush_at)
    : folder_(std::move(folder)), rank_(rank), flush_at_(flush_at), buf_(tiles), files_(tiles) {}

void ScratchWriter::put(std::size_t tile, const PointCloud& c, std::size_t i, std::uint64_t record,
                        const ScratchColumns& cols) {
  put_point(buf_[tile], c, i, record, cols);
  if (buf_[tile].size() >= flush_at_) flush(tile);
}

void ScratchWriter::flush(std::size_t tile) {
  std::string& buf = buf_[tile];
  if (buf.empty()) return;
  std::unique_ptr<std::ofstream>& file = files_[tile];
  if (!file) {
    file = std::make_unique<std::ofstream>(scratch_file(folder_, tile, rank_),
                                           std::ios::binary | std::ios::trunc);
    if (!*file)
      throw IoError(scratch_file(folder_, tile, rank_).string() + ": cannot create a scratch file");
  }
  file->write(buf.data(), static_cast<std::streamsize>(buf.size()));
  if (!*file)
    throw IoError(scratch_file(folder_, tile, rank_).string() + ": write failed (disk full?)");
  buf.clear();
}

void ScratchWriter::finish() {
  for (std::size_t k = 0; k < buf_.size(); ++k) flush(k);
  for (std::size_t k = 0; k < files_.size(); ++k)
    if (files_[k]) {
      files_[k]->close();
      if (!*files_[k])
        throw IoError(scratch_file(folder_, k, rank_).string() +
                      ": a scratch file could not be closed (disk full?)");
    }
}

ScratchCleanup::ScratchCleanup(std::filesystem::path folder, std::size_t tiles, int ranks)
    : folder_(std::move(folder)),
      tiles_(tiles),
      ranks_(std::max(1, ranks)),
      uncaught_(std::uncaught_exceptions()) {}

ScratchCleanup::~ScratchCleanup() {
  if (std::uncaught_exceptions() == uncaught_) return;
  for (std::size_t k = 0; k < tiles_; ++k)
    for (int r = 0; r < ranks_; ++r) {
      std::error_code ec;
      std::filesystem::remove(scratch_file(folder_, k, r), ec);
    }
}

}  // namespace scanclean::detail

// PLY writer (binary little-endian or ascii), atomic.
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "file_bytes.h"
#include "header_comment.h"
#include "ply_encode.h"
#include "position_precision.h"
#include "scanclean/core/atomic_file.h"
#include "scanclean/io/ply.h"

namespace scanclean {
namespace {

using Out = AttributeType;  // the PLY value types are the attribute types

struct OutColumn {
  std::string name;
  Out type;
  std::function<double(std::size_t)> get;
};

using io_detail::clamp_int;

void put_value(std::string& buf, Out t, double v, bool ascii) {
  if (ascii) {
    switch (t) {
      case Out::kUInt8:
        buf += std::to_string(clamp_int<std::uint8_t>(v));
        break;
      case Out::kInt32:
        buf += std::to_string(clamp_int<std::int32_t>(v));
        break;
      case Out::kUInt32:
        buf += std::to_string(clamp_int<std::uint32_t>(v));
        break;
      case Out::kFloat32:
        buf += io_detail::format_float(static_cast<float>(v));
        break;
      case Out::kFloat64:
        buf += io_detail::format_double(v);
        break;
    }
    return;
  }
  io_detail::put_ply_binary(buf, t, v);
}

}  // namespace

void write_ply(const std::filesystem::path& path, const PointCloud& cloud, PlyEncoding encoding,
               const std::string& provenance) {
  cloud.check_consistent();
  const bool ascii = encoding == PlyEncoding::kAscii;
  const std::size_t n = cloud.size();
  std::vector<OutColumn> cols;
  const Out pos_type =
      io_detail::positions_fit_float(cloud.positions) ? Out::kFloat32 : Out::kFloat64;
  for (int k = 0; k < 3; ++k)
    cols.push_back({std::string(1, "xyz"[k]), pos_type,
                    [&cloud, k](std::size_t i) { return cloud.positions[i][k]; }});
  if (cloud.has_normals())
    for (int k = 0; k < 3; ++k)
      cols.push_back({std::string("n") + "xyz"[k], Out::kFloat32,
                      [&cloud, k](std::size_t i) { return double(cloud.normals[i][k]); }});
  if (cloud.has_confidences())
    cols.push_back({"confidence", Out::kFloat32,
                    [&cloud](std::size_t i) { return double(cloud.confidences[i]); }});
  if (cloud.has_intensities())
    cols.push_back({"intensity", Out::kFloat32,
                    [&cloud](std::size_t i) { return double(cloud.intensities[i]); }});
  if (cloud.has_colors()) {
    const char* names[4] = {"red", "green", "blue", "alpha"};
    for (int k = 0; k < 4; ++k)
      cols.push_back({names[k], Out::kUInt8,
                      [&cloud, k](std::size_t i) { return double(cloud.colors[i][k]); }});
  }
  for (const auto& a : cloud.attributes)
    cols.push_back({io_detail::sanitize_ply_name(a.name), a.type,
                    [&a](std::size_t i) { return a.values[i]; }});

  std::string header = "ply\nformat ";
  header += ascii ? "ascii 1.0\n" : "binary_little_endian 1.0\n";
  header += "comment written by scanclean " SCANCLEAN_VERSION " (units: metres)\n";
  if (!provenance.empty()) header += "comment " + io_detail::header_comment_text(provenance) + "\n";
  const bool grid = !cloud.grid.empty();
  if (grid) {
    header += "obj_info num_cols " + std::to_string(cloud.grid.cols) + "\n";
    header += "obj_info num_rows " + std::to_string(cloud.grid.rows) + "\n";
  }
  header += "element vertex " + std::to_string(n) + "\n";
  for (const auto& c : cols)
    header += std::string("property ") + io_detail::ply_type_name(c.type) + " " + c.name + "\n";
  if (grid) {
    header += "element range_grid " + std::to_string(cloud.grid.index.size()) + "\n";
    header += "property list uchar int vertex_indices\n";
  }
  header += "end_header\n";

  write_file_atomically(path, [&](std::ostream& os) {
    os.write(header.data(), static_cast<std::streamsize>(header.size()));
    std::string buf;
    buf.reserve(1 << 20);
    auto flush = [&](bool force) {
      if (force || buf.size() > (1u << 20)) {
        os.write(buf.data(), static_cast<std::streamsize>(buf.size()));
        buf.clear();
      }
    };
    for (std::size_t i = 0; i < n; ++i) {
      for (std::size_t c = 0; c < cols.size(); ++c) {
        if (ascii && c > 0) buf += ' ';
        put_value(buf, cols[c].type, cols[c].get(i), ascii);
      }
      if (ascii) buf += '\n';
      flush(false);
    }
    if (grid) {
      for (std::int32_t idx : cloud.grid.index) {
        if (ascii) {
          buf += idx < 0 ? "0\n" : "1 " + std::to_string(idx) + "\n";
        } else if (idx < 0) {
          io_detail::put_le(buf, std::uint8_t{0});
        } else {
          io_detail::put_le(buf, std::uint8_t{1});
          io_detail::put_le(buf, idx);
        }
        flush(false);
      }
    }
    flush(true);
  });
}

}  // namespace scanclean

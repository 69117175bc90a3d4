// PCD writer (ascii, binary, binary_compressed), atomic.
#include <lzf.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "file_bytes.h"
#include "header_comment.h"
#include "position_precision.h"
#include "scanclean/core/atomic_file.h"
#include "scanclean/core/errors.h"
#include "scanclean/io/pcd.h"

namespace scanclean {
namespace {

struct OutField {
  std::string name;
  char type;                               // F I U
  int size;                                // 1 4 8
  std::function<double(std::size_t)> get;  // point index -> value
  bool packed_rgba = false;                // the value is a uint32 bit pattern
};

OutField attribute_field(const Attribute& a) {
  auto get = [&a](std::size_t i) { return a.values[i]; };
  std::string name = a.name;
  for (char& c : name)
    if (c == ' ' || c == '\t' || c == '\n' || c == '\r') c = '_';
  switch (a.type) {
    case AttributeType::kUInt8:
      return {name, 'U', 1, get};
    case AttributeType::kInt32:
      return {name, 'I', 4, get};
    case AttributeType::kUInt32:
      return {name, 'U', 4, get};
    case AttributeType::kFloat32:
      return {name, 'F', 4, get};
    case AttributeType::kFloat64:
      return {name, 'F', 8, get};
  }
  return {name, 'F', 8, get};
}

template <class I>
I clamp_int(double v) {
  if (std::isnan(v)) return 0;
  return static_cast<I>(
      std::llround(std::clamp(v, static_cast<double>(std::numeric_limits<I>::min()),
                              static_cast<double>(std::numeric_limits<I>::max()))));
}

//! Stores one value at p (little-endian host assumed, as PCD binary is host order in practice).
void store(unsigned char* p, const OutField& f, double v) {
  if (f.type == 'F') {
    if (f.size == 4) {
      const float x = static_cast<float>(v);
      std::memcpy(p, &x, 4);
    } else {
      std::memcpy(p, &v, 8);
    }
  } else if (f.type == 'I') {
    const auto x = clamp_int<std::int32_t>(v);
    std::memcpy(p, &x, 4);
  } else if (f.size == 1) {
    p[0] = clamp_int<std::uint8_t>(v);
  } else {
    const auto x = clamp_int<std::uint32_t>(v);
    std::memcpy(p, &x, 4);
  }
}

std::string ascii_value(const OutField& f, double v) {
  if (f.type == 'F')
    return f.size == 4 ? io_detail::format_float(static_cast<float>(v))
                       : io_detail::format_double(v);
  if (f.type == 'I') return std::to_string(clamp_int<std::int32_t>(v));
  if (f.size == 1) return std::to_string(clamp_int<std::uint8_t>(v));
  return std::to_string(clamp_int<std::uint32_t>(v));
}

}  // namespace

void write_pcd(const std::filesystem::path& path, const PointCloud& cloud,
               const std::string& encoding, const std::string& provenance) {
  if (encoding != "ascii" && encoding != "binary" && encoding != "binary_compressed")
    throw OptionError("pcd encoding '" + encoding +
                      "' is not valid; expected ascii, binary or binary_compressed");
  cloud.check_consistent();

  // Cells in output order: organized when the grid holds every point exactly once.
  std::vector<std::int64_t> order;  // point index per output cell, -1 = empty cell (NaN)
  std::uint64_t width = cloud.size(), height = 1;
  if (!cloud.grid.empty()) {
    std::vector<char> seen(cloud.size(), 0);
    std::size_t filled = 0;
    bool injective = true;
    for (auto idx : cloud.grid.index)
      if (idx >= 0) {
        if (seen[static_cast<std::size_t>(idx)]++) injective = false;
        ++filled;
      }
    if (injective && filled == cloud.size()) {
      order.assign(cloud.grid.index.begin(), cloud.grid.index.end());
      width = static_cast<std::uint64_t>(cloud.grid.cols);
      height = static_cast<std::uint64_t>(cloud.grid.rows);
    }
  }
  if (order.empty() && height == 1) {
    order.resize(cloud.size());
    for (std::size_t i = 0; i < cloud.size(); ++i) order[i] = static_cast<std::int64_t>(i);
  }
  const std::size_t n = order.size();

  std::vector<OutField> fields;
  const bool as_float = io_detail::positions_fit_float(cloud.positions);
  for (int k = 0; k < 3; ++k)
    fields.push_back({std::string(1, "xyz"[k]), 'F', as_float ? 4 : 8,
                      [&cloud, k](std::size_t i) { return cloud.positions[i][k]; }});
  if (cloud.has_normals())
    for (int k = 0; k < 3; ++k)
      fields.push_back({std::string("normal_") + "xyz"[k], 'F', 4,
                        [&cloud, k](std::size_t i) { return double(cloud.normals[i][k]); }});
  if (cloud.has_colors())
    fields.push_back({"rgba", 'U', 4,
                      [&cloud](std::size_t i) {
                        const auto& c = cloud.colors[i];
                        return double((std::uint32_t(c[3]) << 24) | (std::uint32_t(c[0]) << 16) |
                                      (std::uint32_t(c[1]) << 8) | std::uint32_t(c[2]));
                      },
                      true});
  if (cloud.has_intensities())
    fields.push_back(
        {"intensity", 'F', 4, [&cloud](std::size_t i) { return double(cloud.intensities[i]); }});
  if (cloud.has_confidences())
    fields.push_back(
        {"confidence", 'F', 4, [&cloud](std::size_t i) { return double(cloud.confidences[i]); }});
  for (const auto& a : cloud.attributes) fields.push_back(attribute_field(a));

  std::string header =
      "# .PCD v0.7 - Point Cloud Data file format (written by scanclean " SCANCLEAN_VERSION
      "; units: metres)\n";
  if (!provenance.empty()) header += "# " + io_detail::header_comment_text(provenance) + "\n";
  header += "VERSION 0.7\nFIELDS";
  std::string sizes = "SIZE", types = "TYPE", counts = "COUNT";
  std::size_t step = 0;
  std::vector<std::size_t> offsets;
  for (const auto& f : fields) {
    header += " " + f.name;
    sizes += " " + std::to_string(f.size);
    types += std::string(" ") + f.type;
    counts += " 1";
    offsets.push_back(step);
    step += static_cast<std::size_t>(f.size);
  }
  header += "\n" + sizes + "\n" + types + "\n" + counts + "\nWIDTH " + std::to_string(width) +
            "\nHEIGHT " + std::to_string(height) + "\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " +
            std::to_string(n) + "\nDATA " + encoding + "\n";

  auto value = [&](std::size_t f, std::size_t cell) -> double {
    const std::int64_t idx = order[cell];
    if (idx < 0) return f < 3 ? std::numeric_limits<double>::quiet_NaN() : 0.0;
    return fields[f].get(static_cast<std::size_t>(idx));
  };

  write_file_atomically(path, [&](std::ostream& os) {
    os.write(header.data(), static_cast<std::streamsize>(header.size()));
    if (encoding == "ascii") {
      std::string buf;
      for (std::size_t c = 0; c < n; ++c) {
        for (std::size_t f = 0; f < fields.size(); ++f) {
          if (f) buf += ' ';
          buf += ascii_value(fields[f], value(f, c));
        }
        buf += '\n';
        if (buf.size() > (1u << 20)) {
          os.write(buf.data(), static_cast<std::streamsize>(buf.size()));
          buf.clear();
        }
      }
      os.write(buf.data(), static_cast<std::streamsize>(buf.size()));
      return;
    }
    std::vector<unsigned char> data(n * step);
    const bool soa = encoding == "binary_compressed";
    for (std::size_t f = 0; f < fields.size(); ++f)
      for (std::size_t c = 0; c < n; ++c) {
        unsigned char* p = soa ? data.data() + n * offsets[f] + c * fields[f].size
                               : data.data() + c * step + offsets[f];
        store(p, fields[f], value(f, c));
      }
    if (!soa) {
      os.write(reinterpret_cast<const char*>(data.data()),
               static_cast<std::streamsize>(data.size()));
      return;
    }
    if (data.size() > std::numeric_limits<std::uint32_t>::max() / 2)
      throw IoError(path.string() + ": too large for PCD binary_compressed (" +
                    std::to_string(data.size()) + " bytes); use binary");
    std::vector<unsigned char> packed(data.size() + data.size() / 16 + 64);
    unsigned int csize = 0;
    if (!data.empty()) {
      csize = lzf_compress(data.data(), static_cast<unsigned>(data.size()), packed.data(),
                           static_cast<unsigned>(packed.size()));
      if (csize == 0) throw IoError(path.string() + ": LZF compression failed");
    }
    const std::uint32_t sizes2[2] = {csize, static_cast<std::uint32_t>(data.size())};
    os.write(reinterpret_cast<const char*>(sizes2), 8);
    os.write(reinterpret_cast<const char*>(packed.data()), csize);
  });
}

}  // namespace scanclean

// PCD reader: header, ascii / binary / binary_compressed (LZF) bodies.
#include <lzf.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "cloud_assembly.h"
#include "file_bytes.h"
#include "scanclean/core/errors.h"
#include "scanclean/io/pcd.h"

namespace scanclean {
namespace {

using io_detail::Column;
using io_detail::next_token;
using io_detail::quote;

struct Field {
  std::string name;
  int size = 4;
  char type = 'F';
  std::uint64_t count = 1;
  std::uint64_t offset = 0;  // bytes within a point
};

struct PcdHeader {
  std::vector<Field> fields;
  std::uint64_t width = 0, height = 1, points = 0;
  std::uint64_t point_step = 0;
  std::string data;
  std::size_t data_offset = 0;
  std::uint64_t data_line = 0;
};

std::vector<std::string_view> tokens(std::string_view rest) {
  std::vector<std::string_view> out;
  for (std::string_view t = next_token(rest); !t.empty(); t = next_token(rest)) out.push_back(t);
  return out;
}

PcdHeader parse_header(const std::string& bytes, const std::string& file, ReadReport* report) {
  if (bytes.empty()) throw InputError(file, "", "empty file; expected a PCD header");
  PcdHeader h;
  const std::string_view all(bytes);
  std::size_t pos = 0;
  std::uint64_t line = 0;
  bool have_size = false, have_type = false, have_count = false, have_width = false,
       have_points = false, have_fields = false;
  std::uint64_t fields_line = 0;
  auto warn = [&](const std::string& w) {
    if (report) report->warnings.push_back(file + ": " + line_place(line) + ": " + w);
  };
  auto number = [&](std::string_view t, const char* what) -> std::uint64_t {
    const auto v = io_detail::parse_int(t);
    if (!v || *v < 0)
      throw InputError(
          file, line_place(line),
          std::string("expected a non-negative integer for ") + what + ", found " + quote(t));
    return static_cast<std::uint64_t>(*v);
  };
  while (true) {
    if (pos >= all.size())
      throw InputError(file, line_place(line),
                       "the header ends without a DATA line (truncated or not a PCD file)");
    std::size_t e = all.find('\n', pos);
    if (e == std::string_view::npos) e = all.size();
    std::string_view l = all.substr(pos, e - pos);
    pos = e < all.size() ? e + 1 : e;
    ++line;
    if (!l.empty() && l.back() == '\r') l.remove_suffix(1);
    std::string_view rest = l;
    const std::string_view kw = next_token(rest);
    if (kw.empty() || kw.front() == '#') continue;
    const auto t = tokens(rest);
    const std::string place = line_place(line);
    if (kw == "VERSION") {
      if (t.empty() || (t[0] != "0.7" && t[0] != ".7" && t[0] != "0.6" && t[0] != ".6" &&
                        t[0] != "0.5" && t[0] != ".5"))
        warn("PCD version " + (t.empty() ? std::string("''") : quote(t[0])) +
             " (expected 0.7, 0.6 or 0.5); reading it as 0.7");
    } else if (kw == "FIELDS" || kw == "COLUMNS") {
      if (t.empty()) throw InputError(file, place, "FIELDS line without field names");
      if (t.size() > 10000) throw InputError(file, place, "more than 10000 fields");
      h.fields.clear();
      for (auto name : t) h.fields.push_back(Field{std::string(name)});
      have_fields = true;
      fields_line = line;
    } else if (kw == "SIZE" || kw == "TYPE" || kw == "COUNT") {
      if (!have_fields) throw InputError(file, place, std::string(kw) + " before FIELDS");
      if (t.size() != h.fields.size())
        throw InputError(file, place,
                         std::string(kw) + " has " + std::to_string(t.size()) +
                             " entries, FIELDS (" + line_place(fields_line) + ") has " +
                             std::to_string(h.fields.size()));
      for (std::size_t i = 0; i < t.size(); ++i) {
        if (kw == "SIZE") {
          const std::uint64_t s = number(t[i], "SIZE");
          if (s != 1 && s != 2 && s != 4 && s != 8)
            throw InputError(file, place,
                             "SIZE " + std::string(t[i]) + " of field '" + h.fields[i].name +
                                 "' is not 1, 2, 4 or 8");
          h.fields[i].size = static_cast<int>(s);
        } else if (kw == "TYPE") {
          if (t[i].size() != 1 || (t[i][0] != 'F' && t[i][0] != 'I' && t[i][0] != 'U'))
            throw InputError(
                file, place,
                "TYPE " + quote(t[i]) + " of field '" + h.fields[i].name + "'; expected F, I or U");
          h.fields[i].type = t[i][0];
        } else {
          const std::uint64_t c = number(t[i], "COUNT");
          if (c == 0 || c > 1000000)
            throw InputError(file, place,
                             "COUNT " + std::string(t[i]) + " of field '" + h.fields[i].name +
                                 "' is out of range; expected 1..1000000");
          h.fields[i].count = c;
        }
      }
      (kw == "SIZE" ? have_size : kw == "TYPE" ? have_type : have_count) = true;
    } else if (kw == "WIDTH") {
      if (t.size() != 1) throw InputError(file, place, "expected 'WIDTH <n>'");
      h.width = number(t[0], "WIDTH");
      have_width = true;
    } else if (kw == "HEIGHT") {
      if (t.size() != 1) throw InputError(file, place, "expected 'HEIGHT <n>'");
      h.height = number(t[0], "HEIGHT");
    } else if (kw == "POINTS") {
      if (t.size() != 1) throw InputError(file, place, "expected 'POINTS <n>'");
      h.points = number(t[0], "POINTS");
      have_points = true;
    } else if (kw == "VIEWPOINT") {
      static const char* identity[7] = {"0", "0", "0", "1", "0", "0", "0"};
      bool is_identity = t.size() == 7;
      for (std::size_t i = 0; is_identity && i < 7; ++i) {
        const auto v = io_detail::parse_double(t[i]);
        is_identity = v && *v == *io_detail::parse_double(identity[i]);
      }
      if (!is_identity)
        warn("VIEWPOINT " +
             quote(l.substr(l.find_first_not_of(" \t", 9) == std::string_view::npos
                                ? l.size()
                                : l.find_first_not_of(" \t", 9))) +
             " is not applied to the points (kept in sensor frame)");
    } else if (kw == "DATA") {
      if (t.size() != 1 || (t[0] != "ascii" && t[0] != "binary" && t[0] != "binary_compressed"))
        throw InputError(file, place,
                         "unknown DATA encoding " + quote(t.empty() ? std::string_view() : t[0]) +
                             "; expected ascii, binary or binary_compressed");
      h.data = std::string(t[0]);
      break;
    } else {
      warn("unknown header line " + quote(l) + " skipped");
    }
  }
  const std::string hp = "header";
  if (!have_fields) throw InputError(file, hp, "no FIELDS line");
  if (!have_size) throw InputError(file, hp, "no SIZE line");
  if (!have_type) throw InputError(file, hp, "no TYPE line");
  (void)have_count;  // COUNT is optional (defaults to 1)
  for (const auto& f : h.fields)
    if (f.type == 'F' && f.size != 4 && f.size != 8)
      throw InputError(file, hp,
                       "field '" + f.name + "' has TYPE F with SIZE " + std::to_string(f.size) +
                           "; expected SIZE 4 or 8");
  if (!have_width && !have_points) throw InputError(file, hp, "neither WIDTH nor POINTS given");
  if (!have_width) {
    h.width = h.points;
    h.height = 1;
  }
  if (h.height == 0 && h.width != 0)
    throw InputError(file, hp, "HEIGHT 0 with WIDTH " + std::to_string(h.width));
  if (h.width > 0 && h.height > (std::uint64_t{1} << 40) / h.width)
    throw InputError(file, hp, "WIDTH x HEIGHT is implausibly large");
  if (!have_points) h.points = h.width * h.height;
  if (h.points != h.width * h.height)
    throw InputError(file, hp,
                     "POINTS " + std::to_string(h.points) + " differs from WIDTH x HEIGHT = " +
                         std::to_string(h.width) + " x " + std::to_string(h.height));
  std::uint64_t offset = 0;
  for (auto& f : h.fields) {
    f.offset = offset;
    offset += static_cast<std::uint64_t>(f.size) * f.count;
  }
  h.point_step = offset;
  h.data_offset = pos;
  h.data_line = line + 1;
  return h;
}

double load_value(const unsigned char* p, const Field& f) {
  auto get = [p](auto v) {
    std::memcpy(&v, p, sizeof v);
    return v;
  };
  switch (f.type) {
    case 'F':
      return f.size == 4 ? static_cast<double>(get(float{})) : get(double{});
    case 'I':
      switch (f.size) {
        case 1:
          return get(std::int8_t{});
        case 2:
          return get(std::int16_t{});
        case 4:
          return get(std::int32_t{});
        default:
          return static_cast<double>(get(std::int64_t{}));
      }
    default:
      switch (f.size) {
        case 1:
          return get(std::uint8_t{});
        case 2:
          return get(std::uint16_t{});
        case 4:
          return get(std::uint32_t{});
        default:
          return static_cast<double>(get(std::uint64_t{}));
      }
  }
}

std::uint32_t packed_colour(const unsigned char* p, const Field& f) {
  if (f.size == 4) {
    std::uint32_t v;
    std::memcpy(&v, p, 4);  // float or uint32: the bit pattern is the packed colour
    return v;
  }
  return static_cast<std::uint32_t>(load_value(p, f));
}

AttributeType attribute_type(const Field& f) {
  if (f.type == 'F') return f.size == 4 ? AttributeType::kFloat32 : AttributeType::kFloat64;
  if (f.size == 8) return AttributeType::kFloat64;
  if (f.type == 'U') return f.size == 1 ? AttributeType::kUInt8 : AttributeType::kUInt32;
  return AttributeType::kInt32;
}

bool is_colour(const Field& f) {
  return (f.name == "rgb" || f.name == "rgba") && f.count == 1 && f.size == 4;
}

}  // namespace

PointCloud read_pcd(const std::filesystem::path& path, ReadReport* report) {
  const std::string file = path.string();
  const std::string bytes = io_detail::read_file_bytes(path);
  const PcdHeader h = parse_header(bytes, file, report);
  const std::uint64_t n = h.points;
  if (n > static_cast<std::uint64_t>(std::numeric_limits<std::int32_t>::max()))
    throw InputError(file, "header", "POINTS " + std::to_string(n) + " exceeds 2^31-1");
  if (h.point_step > 100000000)
    throw InputError(file, "header",
                     "a point of " + std::to_string(h.point_step) +
                         " bytes (SIZE x COUNT summed) is implausibly large");
  const std::size_t remaining = bytes.size() - h.data_offset;

  // Which fields are used, and the columns they fill.
  std::vector<int> column_of(h.fields.size(), -1);
  std::vector<Column> columns;
  int colour_field = -1;
  for (std::size_t k = 0; k < h.fields.size(); ++k) {
    const Field& f = h.fields[k];
    if (report)
      report->fields.push_back(f.name + ":" + f.type + std::to_string(f.size) +
                               (f.count > 1 ? "x" + std::to_string(f.count) : ""));
    if (f.name == "_") continue;
    if (f.count > 1) {
      if (report)
        report->warnings.push_back(file + ": header: field '" + f.name + "' with COUNT " +
                                   std::to_string(f.count) +
                                   " skipped (only COUNT 1 fields are kept)");
      continue;
    }
    if (is_colour(f) && colour_field < 0) {
      colour_field = static_cast<int>(k);
      continue;
    }
    column_of[k] = static_cast<int>(columns.size());
    Column c;
    c.name = f.name;
    c.type = attribute_type(f);
    c.floating = f.type == 'F';
    columns.push_back(std::move(c));
  }
  // Check declared sizes against the file before allocating anything.
  std::uint64_t values_per_point = 0;
  for (const auto& f : h.fields) values_per_point += f.count;
  if (h.data == "ascii") {
    if (n > 0 && n * 2 * values_per_point > remaining + 1)
      throw InputError(file, line_place(h.data_line),
                       "POINTS " + std::to_string(n) + " with " + std::to_string(values_per_point) +
                           " values each cannot fit in the " + std::to_string(remaining) +
                           " bytes after the header (truncated file or wrong POINTS)");
  } else if (h.data == "binary") {
    if (n * h.point_step > remaining)
      throw InputError(file, byte_place(h.data_offset),
                       "binary data of " + std::to_string(n) + " points x " +
                           std::to_string(h.point_step) +
                           " bytes = " + std::to_string(n * h.point_step) + " bytes expected, " +
                           std::to_string(remaining) + " present (truncated file?)");
  } else if (h.data == "binary_compressed") {
    const auto* base = reinterpret_cast<const unsigned char*>(bytes.data()) + h.data_offset;
    if (remaining < 8)
      throw InputError(file, byte_place(h.data_offset),
                       "binary_compressed data must start with two uint32 sizes; only " +
                           std::to_string(remaining) + " bytes present");
    std::uint32_t csize, usize;
    std::memcpy(&csize, base, 4);
    std::memcpy(&usize, base + 4, 4);
    if (csize > remaining - 8)
      throw InputError(file, byte_place(h.data_offset),
                       "compressed size " + std::to_string(csize) + " exceeds the " +
                           std::to_string(remaining - 8) + " bytes left in the file");
    if (usize != n * h.point_step)
      throw InputError(file, byte_place(h.data_offset + 4),
                       "uncompressed size " + std::to_string(usize) +
                           " differs from POINTS x point size = " + std::to_string(n) + " x " +
                           std::to_string(h.point_step) + " = " + std::to_string(n * h.point_step));
    // LZF expands at most ~88x (264-byte matches in 3-byte codes): reject lying sizes early.
    if (static_cast<std::uint64_t>(usize) > 100ull * csize + 1024)
      throw InputError(file, byte_place(h.data_offset),
                       "uncompressed size " + std::to_string(usize) + " cannot come from a " +
                           std::to_string(csize) + "-byte LZF payload (header or sizes corrupt)");
  }
  for (auto& c : columns) c.values.reserve(n);
  std::vector<std::uint32_t> colours;
  if (colour_field >= 0) colours.reserve(n);

  if (h.data == "ascii") {
    const std::string_view all(bytes);
    std::size_t pos = h.data_offset;
    std::uint64_t line = h.data_line;
    std::uint64_t i = 0;
    std::vector<std::string_view> toks;
    while (i < n) {
      if (pos >= all.size())
        throw InputError(file, line_place(line),
                         "unexpected end of file after " + std::to_string(i) + " of " +
                             std::to_string(n) + " points (truncated file or wrong POINTS)");
      std::size_t e = all.find('\n', pos);
      if (e == std::string_view::npos) e = all.size();
      std::string_view rest = all.substr(pos, e - pos);
      pos = e < all.size() ? e + 1 : e;
      toks.clear();
      for (auto t = next_token(rest); !t.empty(); t = next_token(rest)) toks.push_back(t);
      if (toks.empty()) {
        ++line;
        continue;
      }
      if (toks.size() != values_per_point)
        throw InputError(file, line_place(line),
                         "point " + std::to_string(i) + ": expected " +
                             std::to_string(values_per_point) + " values, found " +
                             std::to_string(toks.size()));
      std::size_t t = 0;
      for (std::size_t k = 0; k < h.fields.size(); ++k) {
        const Field& f = h.fields[k];
        if (static_cast<int>(k) == colour_field) {
          // ascii rgb is written as the float whose bits are the packed colour, or as an integer
          std::uint32_t bits = 0;
          if (f.type == 'F') {
            const auto v = io_detail::parse_double(toks[t]);
            if (!v)
              throw InputError(
                  file, line_place(line),
                  "field '" + f.name + "': expected a number, found " + quote(toks[t]));
            const float fv = static_cast<float>(*v);
            std::memcpy(&bits, &fv, 4);
          } else {
            const auto v = io_detail::parse_int(toks[t]);
            if (!v || *v < std::numeric_limits<std::int32_t>::min() ||
                *v > std::numeric_limits<std::uint32_t>::max())
              throw InputError(
                  file, line_place(line),
                  "field '" + f.name + "': expected a 32-bit integer, found " + quote(toks[t]));
            bits = static_cast<std::uint32_t>(*v);
          }
          colours.push_back(bits);
        } else if (column_of[k] >= 0) {
          const auto v = io_detail::parse_double(toks[t]);
          if (!v)
            throw InputError(file, line_place(line),
                             "field '" + f.name + "' of point " + std::to_string(i) +
                                 ": expected a number, found " + quote(toks[t]));
          columns[static_cast<std::size_t>(column_of[k])].values.push_back(
              f.type == 'F' && f.size == 4 ? static_cast<double>(static_cast<float>(*v)) : *v);
        }
        t += f.count;
      }
      ++i;
      ++line;
    }
    for (std::size_t p = pos; p < all.size(); ++p)
      if (!std::isspace(static_cast<unsigned char>(all[p]))) {
        if (report)
          report->warnings.push_back(file + ": " + line_place(line) +
                                     ": data after the declared POINTS ignored");
        break;
      }
  } else {
    const auto* base = reinterpret_cast<const unsigned char*>(bytes.data()) + h.data_offset;
    std::vector<unsigned char> decompressed;
    bool soa = false;
    if (h.data == "binary_compressed") {
      std::uint32_t csize, usize;
      std::memcpy(&csize, base, 4);
      std::memcpy(&usize, base + 4, 4);
      if (usize > 0) {
        decompressed.resize(usize);
        const unsigned got = lzf_decompress(base + 8, csize, decompressed.data(), usize);
        if (got != usize)
          throw InputError(file, byte_place(h.data_offset + 8),
                           "LZF payload is corrupt: it decodes to " + std::to_string(got) +
                               " bytes, expected " + std::to_string(usize));
      }
      base = decompressed.data();
      soa = true;
    }
    for (std::uint64_t i = 0; i < n; ++i) {
      for (std::size_t k = 0; k < h.fields.size(); ++k) {
        const Field& f = h.fields[k];
        if (column_of[k] < 0 && static_cast<int>(k) != colour_field) continue;
        const unsigned char* p =
            soa ? base + n * f.offset + i * f.count * f.size : base + i * h.point_step + f.offset;
        if (static_cast<int>(k) == colour_field)
          colours.push_back(packed_colour(p, f));
        else
          columns[static_cast<std::size_t>(column_of[k])].values.push_back(load_value(p, f));
      }
    }
    if (h.data == "binary" && n * h.point_step < remaining && report)
      report->warnings.push_back(file + ": " + byte_place(h.data_offset + n * h.point_step) + ": " +
                                 std::to_string(remaining - n * h.point_step) +
                                 " bytes after the declared POINTS ignored");
  }

  if (colour_field >= 0) {
    const bool has_alpha = h.fields[static_cast<std::size_t>(colour_field)].name == "rgba";
    const char* names[4] = {"red", "green", "blue", "alpha"};
    const int shifts[4] = {16, 8, 0, 24};
    for (int c = 0; c < (has_alpha ? 4 : 3); ++c) {
      Column col;
      col.name = names[c];
      col.type = AttributeType::kUInt8;
      col.values.resize(n);
      for (std::uint64_t i = 0; i < n; ++i) col.values[i] = (colours[i] >> shifts[c]) & 0xffu;
      columns.push_back(std::move(col));
    }
  }

  OrganizedGrid grid;
  if (h.height > 1) {
    grid.rows = static_cast<int>(h.height);
    grid.cols = static_cast<int>(h.width);
    grid.index.resize(n);
    for (std::uint64_t i = 0; i < n; ++i) grid.index[i] = static_cast<std::int32_t>(i);
  }
  if (report) {
    report->format = "pcd";
    report->encoding = h.data;
    report->declared_points = n;
  }
  const bool ascii = h.data == "ascii";
  const std::uint64_t first_line = h.data_line;
  return io_detail::assemble_cloud(
      columns, static_cast<std::size_t>(n), std::move(grid), file, "point",
      io_detail::InvalidPolicy::kDrop, report, [&](std::size_t i) {
        return ascii ? line_place(first_line + i) : std::string("point data");
      });
}

}  // namespace scanclean

// PLY reader: header parsing, ascii/binary body decoding, element dispatch.
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <string_view>

#include "cloud_assembly.h"
#include "file_bytes.h"
#include "ply_internal.h"
#include "scanclean/core/errors.h"
#include "scanclean/io/ply.h"
#include "scanclean/io/triangle_mesh_io.h"

namespace scanclean {
namespace {

using io_detail::Column;
using io_detail::next_token;
using io_detail::quote;

enum class PlyType : std::uint8_t {
  kInt8,
  kUInt8,
  kInt16,
  kUInt16,
  kInt32,
  kUInt32,
  kFloat32,
  kFloat64
};

struct TypeInfo {
  const char* name;
  int size;
  bool floating;
  double lo, hi;
  AttributeType attribute;
};

const TypeInfo& info(PlyType t) {
  static const TypeInfo table[] = {
      {"int8", 1, false, -128.0, 127.0, AttributeType::kInt32},
      {"uint8", 1, false, 0.0, 255.0, AttributeType::kUInt8},
      {"int16", 2, false, -32768.0, 32767.0, AttributeType::kInt32},
      {"uint16", 2, false, 0.0, 65535.0, AttributeType::kUInt32},
      {"int32", 4, false, -2147483648.0, 2147483647.0, AttributeType::kInt32},
      {"uint32", 4, false, 0.0, 4294967295.0, AttributeType::kUInt32},
      {"float32", 4, true, 0, 0, AttributeType::kFloat32},
      {"float64", 8, true, 0, 0, AttributeType::kFloat64},
  };
  return table[static_cast<int>(t)];
}

std::optional<PlyType> parse_type(std::string_view s) {
  if (s == "char" || s == "int8") return PlyType::kInt8;
  if (s == "uchar" || s == "uint8") return PlyType::kUInt8;
  if (s == "short" || s == "int16") return PlyType::kInt16;
  if (s == "ushort" || s == "uint16") return PlyType::kUInt16;
  if (s == "int" || s == "int32") return PlyType::kInt32;
  if (s == "uint" || s == "uint32") return PlyType::kUInt32;
  if (s == "float" || s == "float32") return PlyType::kFloat32;
  if (s == "double" || s == "float64") return PlyType::kFloat64;
  return std::nullopt;
}

enum class Format { kAscii, kLittleEndian, kBigEndian };

struct Property {
  std::string name;
  PlyType type = PlyType::kFloat32;
  bool is_list = false;
  PlyType count_type = PlyType::kUInt8;
};

struct Element {
  std::string name;
  std::uint64_t count = 0;
  std::vector<Property> properties;
  std::uint64_t header_line = 0;
};

struct Header {
  Format format = Format::kAscii;
  std::vector<Element> elements;
  std::map<std::string, std::string> obj_info;
  std::size_t data_offset = 0;
  std::uint64_t data_line = 0;
};

const char* kTypeList = "char uchar short ushort int uint float double (or int8 ... float64)";

Header parse_header(const std::string& bytes, const std::string& file, ReadReport* report) {
  if (bytes.empty()) throw InputError(file, "", "empty file; expected a PLY header ('ply' ...)");
  Header h;
  std::size_t pos = 0;
  std::uint64_t line = 0;
  const std::string_view all(bytes);
  auto next_line = [&](std::string_view& out) {
    if (pos >= all.size()) return false;
    std::size_t e = all.find('\n', pos);
    if (e == std::string_view::npos) e = all.size();
    out = all.substr(pos, e - pos);
    if (!out.empty() && out.back() == '\r') out.remove_suffix(1);
    pos = e < all.size() ? e + 1 : e;
    ++line;
    return true;
  };
  std::string_view l;
  next_line(l);
  if (l != "ply")
    throw InputError(file, line_place(1), "expected 'ply' as the first line, found " + quote(l));
  bool have_format = false, ended = false;
  while (next_line(l)) {
    std::string_view rest = l;
    const std::string_view kw = next_token(rest);
    const std::string place = line_place(line);
    if (kw == "end_header") {
      ended = true;
      break;
    } else if (kw == "comment" || kw.empty()) {
      continue;
    } else if (kw == "format") {
      const std::string_view enc = next_token(rest), version = next_token(rest);
      if (enc == "ascii")
        h.format = Format::kAscii;
      else if (enc == "binary_little_endian")
        h.format = Format::kLittleEndian;
      else if (enc == "binary_big_endian")
        h.format = Format::kBigEndian;
      else
        throw InputError(file, place,
                         "unknown PLY format " + quote(enc) +
                             "; expected ascii, binary_little_endian or binary_big_endian");
      if (version != "1.0" && report)
        report->warnings.push_back(file + ": " + place + ": PLY version " + quote(version) +
                                   " (expected 1.0); reading it as 1.0");
      have_format = true;
    } else if (kw == "obj_info") {
      const std::string key(next_token(rest));
      std::string_view value = rest;
      while (!value.empty() && (value.front() == ' ' || value.front() == '\t'))
        value.remove_prefix(1);
      if (!key.empty()) h.obj_info[key] = std::string(value);
    } else if (kw == "element") {
      Element e;
      e.name = std::string(next_token(rest));
      const auto count = io_detail::parse_int(next_token(rest));
      if (e.name.empty() || !count || *count < 0)
        throw InputError(file, place,
                         "expected 'element <name> <count>' with a count >= 0, found " + quote(l));
      e.count = static_cast<std::uint64_t>(*count);
      e.header_line = line;
      h.elements.push_back(std::move(e));
    } else if (kw == "property") {
      if (h.elements.empty())
        throw InputError(file, place, "'property' line before any 'element' line");
      Property p;
      std::string_view t = next_token(rest);
      if (t == "list") {
        const std::string_view ct = next_token(rest), it = next_token(rest);
        const auto c = parse_type(ct), i = parse_type(it);
        if (!c || !i)
          throw InputError(file, place,
                           "unknown list type in " + quote(l) + "; expected 'property list " +
                               "<count type> <item type> <name>' with types " + kTypeList);
        if (info(*c).floating)
          throw InputError(file, place,
                           "list count type must be an integer type, found " + quote(ct));
        p.is_list = true;
        p.count_type = *c;
        p.type = *i;
      } else {
        const auto s = parse_type(t);
        if (!s)
          throw InputError(file, place,
                           "unknown property type " + quote(t) + "; expected one of " + kTypeList);
        p.type = *s;
      }
      p.name = std::string(next_token(rest));
      if (p.name.empty()) throw InputError(file, place, "property without a name: " + quote(l));
      h.elements.back().properties.push_back(std::move(p));
    } else {
      if (report)
        report->warnings.push_back(file + ": " + place + ": unknown header line " + quote(l) +
                                   " skipped");
    }
  }
  if (!ended)
    throw InputError(file, line_place(line),
                     "the header has no 'end_header' line (truncated or not a PLY file)");
  if (!have_format) throw InputError(file, "header", "no 'format' line in the PLY header");
  h.data_offset = pos;
  h.data_line = line + 1;
  return h;
}

//! Decodes values from the body, ascii or binary, with the place (line or byte) for messages.
class Body {
 public:
  Body(const std::string& bytes, const Header& h, const std::string& file)
      : data_(bytes.data()),
        end_(bytes.size()),
        pos_(h.data_offset),
        line_(h.data_line),
        format_(h.format),
        file_(file) {}

  bool ascii() const { return format_ == Format::kAscii; }
  std::size_t pos() const { return pos_; }
  std::size_t remaining() const { return end_ - pos_; }
  void where(const Element* e, std::uint64_t index) {
    element_ = e;
    index_ = index;
  }

  [[noreturn]] void fail(const std::string& what) const {
    std::string ctx;
    if (element_)
      ctx = "element " + element_->name + " " + std::to_string(index_) + " (of " +
            std::to_string(element_->count) + "): ";
    throw InputError(file_, ascii() ? line_place(line_) : byte_place(pos_), ctx + what);
  }

  double value(PlyType t, const Property& p) {
    return ascii() ? ascii_value(t, p) : binary_value(t, p);
  }

  std::uint64_t list_count(const Property& p) {
    const double c = value(p.count_type, p);
    if (c < 0) fail("negative list length " + std::to_string(c) + " for property '" + p.name + "'");
    const auto n = static_cast<std::uint64_t>(c);
    const std::uint64_t min_bytes = ascii() ? 2 : static_cast<std::uint64_t>(info(p.type).size);
    if (n > 0 && n > (remaining() + 1) / min_bytes)
      fail("list property '" + p.name + "' declares " + std::to_string(n) +
           " entries, more than the remaining " + std::to_string(remaining()) +
           " bytes can hold (truncated file?)");
    return n;
  }

  void end_instance() {
    if (!ascii()) return;
    while (pos_ < end_ && (data_[pos_] == ' ' || data_[pos_] == '\t' || data_[pos_] == '\r'))
      ++pos_;
    if (pos_ < end_) {
      if (data_[pos_] != '\n') {
        std::size_t e = pos_;
        while (e < end_ && data_[e] != '\n') ++e;
        fail("expected the end of the line after the values of the " +
             std::to_string(element_->properties.size()) + " properties, found " +
             quote(std::string_view(data_ + pos_, e - pos_)) + " (wrong property count?)");
      }
      ++pos_;
      ++line_;
    }
  }

  //! Skips n bytes of binary data.
  void skip(std::uint64_t n) {
    if (n > remaining())
      fail("unexpected end of file: " + std::to_string(n) + " bytes expected, " +
           std::to_string(remaining()) + " left");
    pos_ += n;
  }

  //! Whatever follows the last element: nothing, or whitespace (ascii).
  bool only_whitespace_left() const {
    if (!ascii()) return pos_ == end_;
    for (std::size_t i = pos_; i < end_; ++i)
      if (data_[i] != ' ' && data_[i] != '\t' && data_[i] != '\r' && data_[i] != '\n') return false;
    return true;
  }
  std::string place() const { return ascii() ? line_place(line_) : byte_place(pos_); }

 private:
  double ascii_value(PlyType t, const Property& p) {
    while (pos_ < end_ && (data_[pos_] == ' ' || data_[pos_] == '\t' || data_[pos_] == '\r'))
      ++pos_;
    if (pos_ >= end_)
      fail(std::string("unexpected end of file: expected a ") + info(t).name +
           " value for property '" + p.name + "' (truncated file or element count too large)");
    if (data_[pos_] == '\n')
      fail(std::string("the line ends early: expected a ") + info(t).name +
           " value for property '" + p.name + "' (too few values on the line)");
    const std::size_t b = pos_;
    while (pos_ < end_ && data_[pos_] != ' ' && data_[pos_] != '\t' && data_[pos_] != '\r' &&
           data_[pos_] != '\n')
      ++pos_;
    const std::string_view tok(data_ + b, pos_ - b);
    const TypeInfo& ti = info(t);
    if (ti.floating) {
      const auto v = io_detail::parse_double(tok);
      if (!v)
        fail(std::string("expected a ") + ti.name + " number for property '" + p.name +
             "', found " + quote(tok));
      return t == PlyType::kFloat32 ? static_cast<double>(static_cast<float>(*v)) : *v;
    }
    double v = 0;
    if (const auto i = io_detail::parse_int(tok)) {
      v = static_cast<double>(*i);
    } else {
      const auto d = io_detail::parse_double(tok);
      if (!d || !std::isfinite(*d) || std::floor(*d) != *d)
        fail(std::string("expected an integer (") + ti.name + ") for property '" + p.name +
             "', found " + quote(tok));
      v = *d;
    }
    if (v < ti.lo || v > ti.hi)
      fail("value " + std::string(tok) + " of property '" + p.name + "' is out of range for " +
           ti.name);
    return v;
  }

  template <class T>
  T load() {
    T v;
    std::memcpy(&v, data_ + pos_, sizeof(T));
    const bool swap =
        (format_ == Format::kBigEndian) == (std::endian::native == std::endian::little);
    if (swap && sizeof(T) > 1) {
      unsigned char b[sizeof(T)];
      std::memcpy(b, &v, sizeof(T));
      std::reverse(b, b + sizeof(T));
      std::memcpy(&v, b, sizeof(T));
    }
    pos_ += sizeof(T);
    return v;
  }

  double binary_value(PlyType t, const Property& p) {
    const TypeInfo& ti = info(t);
    if (remaining() < static_cast<std::size_t>(ti.size))
      fail(std::string("unexpected end of file: expected ") + std::to_string(ti.size) + " bytes (" +
           ti.name + ") for property '" + p.name + "', " + std::to_string(remaining()) +
           " left (truncated file or element count too large)");
    switch (t) {
      case PlyType::kInt8:
        return load<std::int8_t>();
      case PlyType::kUInt8:
        return load<std::uint8_t>();
      case PlyType::kInt16:
        return load<std::int16_t>();
      case PlyType::kUInt16:
        return load<std::uint16_t>();
      case PlyType::kInt32:
        return load<std::int32_t>();
      case PlyType::kUInt32:
        return load<std::uint32_t>();
      case PlyType::kFloat32:
        return load<float>();
      case PlyType::kFloat64:
        return load<double>();
    }
    return 0;
  }

  const char* data_;
  std::size_t end_;
  std::size_t pos_;
  std::uint64_t line_;
  Format format_;
  const std::string& file_;
  const Element* element_ = nullptr;
  std::uint64_t index_ = 0;
};

//! Rejects headers that declare more data than the file can hold, before anything is allocated.
void check_sizes(const Header& h, std::size_t file_size, const std::string& file) {
  const double remaining = static_cast<double>(file_size - h.data_offset);
  double need = 0;
  for (const auto& e : h.elements) {
    double per = 0;
    for (const auto& p : e.properties) {
      if (h.format == Format::kAscii)
        per += 2;
      else
        per += info(p.is_list ? p.count_type : p.type).size;
    }
    if (h.format == Format::kAscii && per == 0) per = 1;
    need += per * static_cast<double>(e.count);
    if (need > remaining + 1)
      throw InputError(file, line_place(e.header_line),
                       "element " + e.name + " declares " + std::to_string(e.count) +
                           " entries; with the elements before it that needs at least " +
                           io_detail::format_double(std::floor(need)) + " bytes, but only " +
                           std::to_string(file_size - h.data_offset) +
                           " bytes follow the header (truncated file or wrong count)");
  }
}

void skip_element(Body& body, const Element& e) {
  const bool all_scalar = std::none_of(e.properties.begin(), e.properties.end(),
                                       [](const Property& p) { return p.is_list; });
  if (!body.ascii() && all_scalar) {
    std::uint64_t size = 0;
    for (const auto& p : e.properties) size += static_cast<std::uint64_t>(info(p.type).size);
    body.where(&e, 0);
    body.skip(size * e.count);
    return;
  }
  for (std::uint64_t i = 0; i < e.count; ++i) {
    body.where(&e, i);
    for (const auto& p : e.properties) {
      if (p.is_list) {
        const std::uint64_t n = body.list_count(p);
        if (!body.ascii()) {
          body.skip(n * static_cast<std::uint64_t>(info(p.type).size));
        } else {
          for (std::uint64_t k = 0; k < n; ++k) body.value(p.type, p);
        }
      } else {
        body.value(p.type, p);
      }
    }
    body.end_instance();
  }
}

const char* format_name(Format f) {
  switch (f) {
    case Format::kAscii:
      return "ascii";
    case Format::kLittleEndian:
      return "binary_little_endian";
    case Format::kBigEndian:
      return "binary_big_endian";
  }
  return "";
}

std::optional<int> obj_info_int(const Header& h, const std::string& key) {
  auto it = h.obj_info.find(key);
  if (it == h.obj_info.end()) return std::nullopt;
  std::string_view v = it->second;
  const auto i = io_detail::parse_int(next_token(v));
  if (!i || *i <= 0 || *i > 1000000) return std::nullopt;
  return static_cast<int>(*i);
}

}  // namespace

namespace io_detail {

PlyContent read_ply_content(const std::filesystem::path& path, ReadReport* report, bool mesh) {
  const std::string file = path.string();
  const std::string bytes = read_file_bytes(path);
  const Header h = parse_header(bytes, file, report);
  check_sizes(h, bytes.size(), file);

  const Element* vertex = nullptr;
  for (const auto& e : h.elements)
    if (e.name == "vertex") {
      vertex = &e;
      break;
    }
  if (!vertex)
    throw InputError(file, "header", "no 'element vertex' in the header; expected the points");
  if (vertex->count > static_cast<std::uint64_t>(std::numeric_limits<std::int32_t>::max()))
    throw InputError(
        file, line_place(vertex->header_line),
        "too many vertices (" + std::to_string(vertex->count) + "); at most 2^31-1 are supported");
  const std::size_t n = static_cast<std::size_t>(vertex->count);
  for (const char* axis : {"x", "y", "z"}) {
    const bool found =
        std::any_of(vertex->properties.begin(), vertex->properties.end(),
                    [axis](const Property& p) { return !p.is_list && p.name == axis; });
    if (!found)
      throw InputError(
          file, line_place(vertex->header_line),
          std::string("element vertex has no scalar property ") + axis + "; expected x, y and z");
  }

  if (report) {
    report->format = "ply";
    report->encoding = format_name(h.format);
    report->declared_points = n;
    for (const auto& p : vertex->properties)
      report->fields.push_back(p.name + ":" + (p.is_list ? "list " : "") + info(p.type).name);
  }

  PlyContent out;
  std::vector<Column> columns;
  std::vector<int> column_of;  // per vertex property: column index or -1 (list)
  for (const auto& p : vertex->properties) {
    if (p.is_list) {
      column_of.push_back(-1);
      if (report)
        report->warnings.push_back(file + ": " + line_place(vertex->header_line) +
                                   ": list property '" + p.name +
                                   "' of the vertex element skipped");
      continue;
    }
    column_of.push_back(static_cast<int>(columns.size()));
    Column c;
    c.name = p.name;
    c.type = info(p.type).attribute;
    c.floating = info(p.type).floating;
    c.values.reserve(n);
    columns.push_back(std::move(c));
  }

  OrganizedGrid grid;
  bool vertex_done = false;
  Body body(bytes, h, file);
  for (const auto& e : h.elements) {
    if (&e == vertex) {
      for (std::uint64_t i = 0; i < e.count; ++i) {
        body.where(&e, i);
        for (std::size_t k = 0; k < e.properties.size(); ++k) {
          const Property& p = e.properties[k];
          if (p.is_list) {
            const std::uint64_t m = body.list_count(p);
            for (std::uint64_t j = 0; j < m; ++j) body.value(p.type, p);
          } else {
            columns[static_cast<std::size_t>(column_of[k])].values.push_back(body.value(p.type, p));
          }
        }
        body.end_instance();
      }
      vertex_done = true;
    } else if (!mesh && e.name == "range_grid" && e.properties.size() == 1 &&
               e.properties[0].is_list && !info(e.properties[0].type).floating) {
      const auto rows = obj_info_int(h, "num_rows"), cols = obj_info_int(h, "num_cols");
      const bool usable =
          rows && cols &&
          static_cast<std::uint64_t>(*rows) * static_cast<std::uint64_t>(*cols) == e.count;
      if (!usable && report)
        report->warnings.push_back(
            file + ": " + line_place(e.header_line) + ": range_grid with " +
            std::to_string(e.count) +
            " cells does not match obj_info num_rows x num_cols; the grid is ignored");
      if (usable) {
        grid.rows = *rows;
        grid.cols = *cols;
        grid.index.reserve(e.count);
      }
      const Property& p = e.properties[0];
      for (std::uint64_t i = 0; i < e.count; ++i) {
        body.where(&e, i);
        const std::uint64_t m = body.list_count(p);
        std::int32_t cell = -1;
        for (std::uint64_t j = 0; j < m; ++j) {
          const double v = body.value(p.type, p);
          if (!(v >= 0 && v < static_cast<double>(n)))  // NaN fails too
            body.fail("vertex index " + io_detail::format_double(v) +
                      " out of range; expected 0.." + std::to_string(n) + "-1");
          if (j == 0) cell = static_cast<std::int32_t>(v);
        }
        body.end_instance();
        if (usable) grid.index.push_back(cell);
      }
    } else if (mesh && e.name == "face") {
      int list_prop = -1;
      for (std::size_t k = 0; k < e.properties.size(); ++k)
        if (e.properties[k].is_list &&
            (e.properties[k].name == "vertex_indices" || e.properties[k].name == "vertex_index"))
          list_prop = static_cast<int>(k);
      if (list_prop < 0)
        throw InputError(file, line_place(e.header_line),
                         "element face has no list property vertex_indices (or vertex_index)");
      out.triangles.reserve(e.count);
      std::size_t degenerate = 0;
      std::vector<int> poly;
      for (std::uint64_t i = 0; i < e.count; ++i) {
        body.where(&e, i);
        for (std::size_t k = 0; k < e.properties.size(); ++k) {
          const Property& p = e.properties[k];
          if (!p.is_list) {
            body.value(p.type, p);
            continue;
          }
          const std::uint64_t m = body.list_count(p);
          poly.clear();
          for (std::uint64_t j = 0; j < m; ++j) {
            const double v = body.value(p.type, p);
            if (static_cast<int>(k) != list_prop) continue;
            if (!(v >= 0 && v < static_cast<double>(n)))  // NaN fails too
              body.fail("vertex index " + io_detail::format_double(v) +
                        " out of range; expected 0.." + std::to_string(n) + "-1");
            poly.push_back(static_cast<int>(v));
          }
          if (static_cast<int>(k) != list_prop) continue;
          if (poly.size() < 3) {
            ++degenerate;
            continue;
          }
          for (std::size_t j = 1; j + 1 < poly.size(); ++j)
            out.triangles.push_back({poly[0], poly[j], poly[j + 1]});
        }
        body.end_instance();
      }
      if (degenerate > 0 && report)
        report->warnings.push_back(file + ": " + std::to_string(degenerate) +
                                   " faces with fewer than 3 corners skipped");
    } else {
      if (report)
        report->warnings.push_back(file + ": element " + e.name + " (" + std::to_string(e.count) +
                                   " entries) skipped: not used by the " +
                                   (mesh ? "mesh" : "point-cloud") + " reader");
      skip_element(body, e);
    }
  }
  (void)vertex_done;
  if (!body.only_whitespace_left() && report)
    report->warnings.push_back(file + ": " + body.place() +
                               ": data after the last declared element ignored");

  const Format fmt = h.format;
  const std::uint64_t first_line = h.data_line;
  const bool vertex_first = &h.elements.front() == vertex;
  out.cloud = assemble_cloud(
      columns, n, std::move(grid), file, "vertex",
      mesh ? InvalidPolicy::kReject : InvalidPolicy::kDrop, report, [&](std::size_t i) {
        return fmt == Format::kAscii && vertex_first ? line_place(first_line + i)
                                                     : std::string("vertex data");
      });
  return out;
}

}  // namespace io_detail

PointCloud read_ply(const std::filesystem::path& path, ReadReport* report) {
  return io_detail::read_ply_content(path, report, false).cloud;
}

TriangleMesh read_triangle_mesh(const std::filesystem::path& ply, ReadReport* report) {
  ReadReport local;
  io_detail::PlyContent c = io_detail::read_ply_content(ply, report ? report : &local, true);
  if (c.triangles.empty())
    throw InputError(ply.string(), "header",
                     "no triangles: expected an element face with polygons");
  TriangleMesh mesh;
  mesh.vertices = std::move(c.cloud.positions);
  mesh.triangles = std::move(c.triangles);
  return mesh;
}

}  // namespace scanclean

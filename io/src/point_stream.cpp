// Streaming reads of binary PLY / PCD by record ranges (point_stream.h).
#include "scanclean/io/point_stream.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <string_view>

#include "cloud_assembly.h"
#include "file_bytes.h"
#include "scanclean/core/errors.h"

namespace scanclean {

namespace {

// Field types: the PLY ones in their order, then PCD's 8-byte integers.
enum Type : int { kI8, kU8, kI16, kU16, kI32, kU32, kF32, kF64, kI64, kU64 };
constexpr int kTypeSize[] = {1, 1, 2, 2, 4, 4, 4, 8, 8, 8};

int ply_type(std::string_view s) {
  if (s == "char" || s == "int8") return kI8;
  if (s == "uchar" || s == "uint8") return kU8;
  if (s == "short" || s == "int16") return kI16;
  if (s == "ushort" || s == "uint16") return kU16;
  if (s == "int" || s == "int32") return kI32;
  if (s == "uint" || s == "uint32") return kU32;
  if (s == "float" || s == "float32") return kF32;
  if (s == "double" || s == "float64") return kF64;
  return -1;
}

int pcd_type(char t, long size) {
  if (t == 'F' && size == 4) return kF32;
  if (t == 'F' && size == 8) return kF64;
  if (t == 'I')
    return size == 1 ? kI8 : size == 2 ? kI16 : size == 4 ? kI32 : size == 8 ? kI64 : -1;
  if (t == 'U')
    return size == 1 ? kU8 : size == 2 ? kU16 : size == 4 ? kU32 : size == 8 ? kU64 : -1;
  return -1;
}

// The attribute type the whole-file readers give a field of this type (ply_read, pcd_read).
AttributeType attribute_type(int type) {
  switch (type) {
    case kU8:
      return AttributeType::kUInt8;
    case kU16:
    case kU32:
      return AttributeType::kUInt32;
    case kI8:
    case kI16:
    case kI32:
      return AttributeType::kInt32;
    case kF32:
      return AttributeType::kFloat32;
    default:  // kF64, kI64, kU64
      return AttributeType::kFloat64;
  }
}

bool floating(int type) {
  return type == kF32 || type == kF64;
}

template <class T>
T load(const unsigned char* p, bool swap) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  if (swap) {
    unsigned char b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    std::reverse(b, b + sizeof(T));
    std::memcpy(&v, b, sizeof(T));
  }
  return v;
}

double value(const unsigned char* p, int type, bool swap) {
  switch (type) {
    case kI8:
      return static_cast<std::int8_t>(p[0]);
    case kU8:
      return p[0];
    case kI16:
      return load<std::int16_t>(p, swap);
    case kU16:
      return load<std::uint16_t>(p, swap);
    case kI32:
      return load<std::int32_t>(p, swap);
    case kU32:
      return load<std::uint32_t>(p, swap);
    case kF32:
      return load<float>(p, swap);
    case kF64:
      return load<double>(p, swap);
    case kI64:
      return static_cast<double>(load<std::int64_t>(p, swap));
    default:
      return static_cast<double>(load<std::uint64_t>(p, swap));
  }
}

void pread_all(int fd, const std::filesystem::path& path, std::uint64_t offset, char* buf,
               std::size_t n) {
  std::size_t done = 0;
  while (done < n) {
    const ssize_t r = ::pread(fd, buf + done, n - done, static_cast<off_t>(offset + done));
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0)
      throw IoError(
          path.string() + ": " + byte_place(offset + done) + ": read failed" +
          (r < 0 ? std::string(": ") + std::strerror(errno) : ": unexpected end of file"));
    done += static_cast<std::size_t>(r);
  }
}

}  // namespace

// Parses the header of a stream; a friend of PointStream.
struct PointStreamParser {
  PointStream& s;
  std::string file;
  std::string head;  // the header bytes read so far
  struct Named {
    std::string name;
    PointStream::Field field;
  };
  std::vector<Named> fields;  // the record's scalar fields a cloud can take, in file order

  // Maps the fields to the cloud as assemble_cloud (cloud_assembly.h) maps the whole-file
  // readers' columns: the first field of a name; normals and colours only when complete; every
  // field left over becomes an attribute unless one of its name exists already.
  void assign(bool packed_colour) {
    std::vector<bool> used(fields.size(), false);
    auto find = [&](const char* name) {
      for (std::size_t i = 0; i < fields.size(); ++i)
        if (fields[i].name == name) return static_cast<int>(i);
      return -1;
    };
    auto take = [&](int i, PointStream::Field& f) {
      if (i < 0) return;
      f = fields[static_cast<std::size_t>(i)].field;
      used[static_cast<std::size_t>(i)] = true;
    };
    const int xyz[3] = {find("x"), find("y"), find("z")};
    if (xyz[0] < 0 || xyz[1] < 0 || xyz[2] < 0) fail("header", "no x, y and z fields");
    for (int a = 0; a < 3; ++a) take(xyz[a], s.xyz_[a]);
    int n[3] = {find("nx"), find("ny"), find("nz")};
    if (n[0] < 0 || n[1] < 0 || n[2] < 0) {
      n[0] = find("normal_x");
      n[1] = find("normal_y");
      n[2] = find("normal_z");
    }
    if (n[0] >= 0 && n[1] >= 0 && n[2] >= 0)
      for (int a = 0; a < 3; ++a) take(n[a], s.n_[a]);
    take(find("confidence"), s.conf_);
    take(find("intensity"), s.inten_);
    int c[4] = {find("red"), find("green"), find("blue"), find("alpha")};
    if (c[0] < 0 || c[1] < 0 || c[2] < 0) {
      c[0] = find("diffuse_red");
      c[1] = find("diffuse_green");
      c[2] = find("diffuse_blue");
      c[3] = find("diffuse_alpha");
    }
    if (c[0] >= 0 && c[1] >= 0 && c[2] >= 0) {
      for (int a = 0; a < 4; ++a) take(c[a], s.rgba_[a]);
      s.colors_ = true;
    } else if (packed_colour) {
      s.colors_ = s.packed_colour_ = true;  // rgba_[0] holds the packed field
    }
    for (std::size_t i = 0; i < fields.size(); ++i) {
      if (used[i]) continue;
      const std::string& name = fields[i].name;
      if (std::any_of(s.attribute_types_.begin(), s.attribute_types_.end(),
                      [&](const auto& a) { return a.first == name; }))
        continue;
      s.attribute_fields_.push_back(fields[i].field);
      s.attribute_types_.emplace_back(name, attribute_type(fields[i].field.type));
    }
  }

  [[noreturn]] void fail(const std::string& place, const std::string& what) const {
    throw InputError(file, place, what);
  }

  // Reads the header: everything up to and including the line for which `last(line)` is true.
  template <class Last>
  std::size_t read_header(Last&& last) {
    const std::uint64_t file_size = std::filesystem::file_size(s.path_);
    std::size_t pos = 0;
    while (true) {
      const std::size_t nl = head.find('\n', pos);
      if (nl == std::string::npos) {
        if (head.size() >= (1u << 20)) fail("header", "no end of header within 1 MiB");
        const std::size_t want = std::min<std::uint64_t>(65536, file_size - head.size());
        if (want == 0) fail("header", "the file ends inside the header (truncated?)");
        const std::size_t old = head.size();
        head.resize(old + want);
        pread_all(s.fd_, s.path_, old, head.data() + old, want);
        continue;
      }
      std::string_view line(head.data() + pos, nl - pos);
      if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
      pos = nl + 1;
      if (last(line)) return pos;
    }
  }

  void ply() {
    int line_no = 0;
    bool in_vertex = false, vertex_seen = false, format_seen = false;
    std::uint64_t before_vertex = 0;  // bytes per file of the fixed-size elements before
    std::uint64_t element_count = 0, element_bytes = 0;
    bool element_fixed = true;
    auto close_element = [&] {
      if (!vertex_seen && !in_vertex) {
        if (!element_fixed && element_count > 0)
          fail("header",
               "an element with list properties comes before the vertices: not "
               "streamable (use the whole-file reader)");
        before_vertex += element_count * element_bytes;
      }
      if (in_vertex) vertex_seen = true;
      in_vertex = false;
    };
    s.data_ = read_header([&](std::string_view line) {
      ++line_no;
      const std::string place = "line " + std::to_string(line_no);
      std::string_view rest = line;
      const std::string_view kw = io_detail::next_token(rest);
      if (line_no == 1) {
        if (kw != "ply") fail(place, "expected \"ply\" (not a PLY file)");
        return false;
      }
      if (kw == "format") {
        const std::string_view f = io_detail::next_token(rest);
        if (f == "ascii")
          fail(place,
               "ASCII PLY is not streamable (convert it to binary, or use the whole-file "
               "reader)");
        if (f != "binary_little_endian" && f != "binary_big_endian")
          fail(place, "unknown format " + io_detail::quote(f));
        s.big_endian_ = f == "binary_big_endian";
        format_seen = true;
      } else if (kw == "element") {
        close_element();
        const std::string_view name = io_detail::next_token(rest);
        const auto n = io_detail::parse_int(io_detail::next_token(rest));
        if (!n || *n < 0) fail(place, "expected an element count");
        element_count = static_cast<std::uint64_t>(*n);
        element_bytes = 0;
        element_fixed = true;
        in_vertex = name == "vertex";
        if (in_vertex) {
          if (vertex_seen) fail(place, "a second vertex element");
          s.records_ = element_count;
        }
      } else if (kw == "property") {
        const std::string_view t = io_detail::next_token(rest);
        if (t == "list") {
          if (in_vertex)
            fail(place,
                 "a list property in the vertex element is not streamable (use the "
                 "whole-file reader)");
          element_fixed = false;
          return false;
        }
        const int type = ply_type(t);
        if (type < 0) fail(place, "unknown property type " + io_detail::quote(t));
        const std::string_view name = io_detail::next_token(rest);
        if (in_vertex)
          fields.push_back({std::string(name), {type, static_cast<std::uint32_t>(element_bytes)}});
        element_bytes += kTypeSize[type];
        if (in_vertex) s.stride_ = element_bytes;
      } else if (kw == "end_header") {
        close_element();
        return true;
      } else if (kw != "comment" && kw != "obj_info" && !kw.empty()) {
        // Unknown header lines are skipped, as the whole-file reader does.
      }
      return false;
    });
    if (!format_seen) fail("header", "no format line");
    if (!vertex_seen) fail("header", "no vertex element");
    s.data_ += before_vertex;
    assign(false);
  }

  void pcd() {
    int line_no = 0;
    std::vector<std::string> names;
    std::vector<long> sizes, counts;
    std::vector<char> types;
    std::uint64_t points = 0;
    bool points_seen = false;
    s.data_ = read_header([&](std::string_view line) {
      ++line_no;
      const std::string place = "line " + std::to_string(line_no);
      std::string_view rest = line;
      const std::string_view kw = io_detail::next_token(rest);
      std::vector<std::string_view> t;
      for (auto tok = io_detail::next_token(rest); !tok.empty(); tok = io_detail::next_token(rest))
        t.push_back(tok);
      auto ints = [&](std::vector<long>& v) {
        v.clear();
        for (auto x : t) {
          const auto n = io_detail::parse_int(x);
          if (!n || *n < 0) fail(place, "expected non-negative integers after " + std::string(kw));
          v.push_back(static_cast<long>(*n));
        }
      };
      if (kw.empty() || kw.front() == '#') return false;
      if (kw == "FIELDS") {
        names.assign(t.begin(), t.end());
      } else if (kw == "SIZE") {
        ints(sizes);
      } else if (kw == "TYPE") {
        types.clear();
        for (auto x : t) types.push_back(x.empty() ? '?' : x[0]);
      } else if (kw == "COUNT") {
        ints(counts);
      } else if (kw == "POINTS") {
        std::vector<long> v;
        ints(v);
        if (v.size() != 1) fail(place, "expected one point count");
        points = static_cast<std::uint64_t>(v[0]);
        points_seen = true;
      } else if (kw == "DATA") {
        if (t.size() != 1) fail(place, "expected DATA ascii, binary or binary_compressed");
        if (t[0] == "ascii")
          fail(place,
               "ASCII PCD is not streamable (convert it to binary, or use the whole-file "
               "reader)");
        if (t[0] == "binary_compressed")
          fail(place,
               "binary_compressed PCD is not streamable (convert it with scanclean "
               "convert --pcd-encoding binary, or use the whole-file reader)");
        if (t[0] != "binary") fail(place, "unknown DATA encoding " + io_detail::quote(t[0]));
        return true;
      }
      return false;
    });
    if (counts.empty()) counts.assign(names.size(), 1);
    if (names.empty() || sizes.size() != names.size() || types.size() != names.size() ||
        counts.size() != names.size())
      fail("header", "FIELDS, SIZE, TYPE and COUNT must list the same number of fields");
    if (!points_seen) fail("header", "no POINTS line");
    s.records_ = points;
    std::uint64_t off = 0;
    bool packed = false;
    for (std::size_t k = 0; k < names.size(); ++k) {
      const int type = pcd_type(types[k], sizes[k]);
      if (type < 0)
        fail("header", "field " + names[k] + ": unknown TYPE/SIZE " + std::string(1, types[k]) +
                           std::to_string(sizes[k]));
      PointStream::Field f{type, static_cast<std::uint32_t>(off)};
      const std::string& n = names[k];
      // As read_pcd: COUNT 1 fields only, "_" is padding, the first rgb / rgba of 4 bytes is
      // the packed colour.
      if (counts[k] == 1 && n != "_") {
        if ((n == "rgb" || n == "rgba") && sizes[k] == 4 && !packed) {
          s.rgba_[0] = f;
          s.packed_alpha_ = n == "rgba";
          packed = true;
        } else {
          fields.push_back({n, f});
        }
      }
      off += static_cast<std::uint64_t>(sizes[k]) * static_cast<std::uint64_t>(counts[k]);
    }
    s.stride_ = off;
    assign(packed);
  }

  void finish() {
    s.normals_ = s.n_[0].type >= 0 && s.n_[1].type >= 0 && s.n_[2].type >= 0;
    s.confidence_ = s.conf_.type;
    s.intensity_ = s.inten_.type;
    if (s.stride_ == 0) fail("header", "records of zero bytes");
    const std::uint64_t size = std::filesystem::file_size(s.path_);
    if (s.records_ > (size - std::min(size, s.data_)) / s.stride_)
      fail(byte_place(s.data_), "the header declares " + std::to_string(s.records_) +
                                    " records of " + std::to_string(s.stride_) +
                                    " bytes, but the file holds only " +
                                    std::to_string(size - std::min(size, s.data_)) +
                                    " bytes after the header (truncated?)");
  }
};

std::unique_ptr<PointStream> PointStream::open(const std::filesystem::path& path) {
  std::unique_ptr<PointStream> s(new PointStream);
  s->path_ = path;
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  if (ext != ".ply" && ext != ".pcd")
    throw InputError(path.string(), "file name",
                     "streaming reads need a binary .ply or .pcd file, got " +
                         io_detail::quote(ext.empty() ? path.filename().string() : ext));
  s->pcd_ = ext == ".pcd";
  s->fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (s->fd_ < 0) throw IoError(path.string() + ": cannot open: " + std::strerror(errno));
  PointStreamParser p{*s, path.string(), {}, {}};
  if (s->pcd_)
    p.pcd();
  else
    p.ply();
  p.finish();
  return s;
}

bool PointStream::streamable(const std::filesystem::path& path) {
  try {
    open(path);
    return true;
  } catch (const std::exception&) {
    return false;
  }
}

PointStream::~PointStream() {
  if (fd_ >= 0) ::close(fd_);
}

void PointStream::read(std::uint64_t first, std::uint64_t count, PointCloud& out,
                       std::vector<std::uint64_t>* records) const {
  out = PointCloud{};
  if (records) records->clear();
  if (first >= records_) return;
  count = std::min(count, records_ - first);
  std::vector<char> buf(static_cast<std::size_t>(count * stride_));
  pread_all(fd_, path_, data_ + first * stride_, buf.data(), buf.size());
  const bool swap = big_endian_ != (std::endian::native == std::endian::big);
  out.positions.reserve(count);
  if (normals_) out.normals.reserve(count);
  if (confidence_ >= 0) out.confidences.reserve(count);
  if (intensity_ >= 0) out.intensities.reserve(count);
  if (colors_) out.colors.reserve(count);
  for (const auto& [name, type] : attribute_types_) {
    out.attributes.push_back(Attribute{name, type, {}});
    out.attributes.back().values.reserve(count);
  }
  if (records) records->reserve(count);
  for (std::uint64_t i = 0; i < count; ++i) {
    const auto* r = reinterpret_cast<const unsigned char*>(buf.data()) + i * stride_;
    const Eigen::Vector3d p(value(r + xyz_[0].offset, xyz_[0].type, swap),
                            value(r + xyz_[1].offset, xyz_[1].type, swap),
                            value(r + xyz_[2].offset, xyz_[2].type, swap));
    if (!p.allFinite()) continue;
    out.positions.push_back(p);
    if (records) records->push_back(first + i);
    if (normals_)
      out.normals.emplace_back(static_cast<float>(value(r + n_[0].offset, n_[0].type, swap)),
                               static_cast<float>(value(r + n_[1].offset, n_[1].type, swap)),
                               static_cast<float>(value(r + n_[2].offset, n_[2].type, swap)));
    if (confidence_ >= 0)
      out.confidences.push_back(static_cast<float>(value(r + conf_.offset, conf_.type, swap)));
    if (intensity_ >= 0)
      out.intensities.push_back(static_cast<float>(value(r + inten_.offset, inten_.type, swap)));
    if (colors_) {
      std::array<std::uint8_t, 4> c{};
      if (packed_colour_) {
        const std::uint32_t v = load<std::uint32_t>(r + rgba_[0].offset, swap);
        c = {static_cast<std::uint8_t>(v >> 16), static_cast<std::uint8_t>(v >> 8),
             static_cast<std::uint8_t>(v),
             packed_alpha_ ? static_cast<std::uint8_t>(v >> 24) : std::uint8_t{255}};
      } else {
        for (int a = 0; a < 4; ++a) {
          const Field& f = rgba_[static_cast<std::size_t>(a)];
          c[static_cast<std::size_t>(a)] =
              f.type >= 0
                  ? io_detail::to_colour_byte(value(r + f.offset, f.type, swap), floating(f.type))
                  : std::uint8_t{255};
        }
      }
      out.colors.push_back(c);
    }
    for (std::size_t a = 0; a < attribute_fields_.size(); ++a)
      out.attributes[a].values.push_back(
          value(r + attribute_fields_[a].offset, attribute_fields_[a].type, swap));
  }
}

void PointStream::for_each_chunk(
    std::uint64_t first, std::uint64_t count, std::size_t chunk,
    const std::function<void(const PointCloud&, const std::vector<std::uint64_t>&)>& f) const {
  chunk = std::max<std::size_t>(1, chunk);
  const std::uint64_t end = std::min(records_, first + count);
  PointCloud c;
  std::vector<std::uint64_t> rec;
  for (std::uint64_t b = first; b < end; b += chunk) {
    read(b, std::min<std::uint64_t>(chunk, end - b), c, &rec);
    f(c, rec);
  }
}

std::array<std::uint64_t, 2> PointStream::split(std::uint64_t records, int rank, int ranks) {
  const auto r = static_cast<std::uint64_t>(rank), n = static_cast<std::uint64_t>(ranks);
  // records / n whole parts plus the remainder spread: no overflow for any count.
  const auto at = [&](std::uint64_t k) { return records / n * k + records % n * k / n; };
  return {at(r), at(r + 1)};
}

}  // namespace scanclean

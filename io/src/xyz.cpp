#include "scanclean/io/xyz.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <string>
#include <string_view>

#include "file_bytes.h"
#include "scanclean/core/atomic_file.h"
#include "scanclean/core/errors.h"

namespace scanclean {

namespace {

constexpr std::size_t kMaxColumns = 64;

const std::vector<std::string>& known_names() {
  static const std::vector<std::string> names{"x", "y", "z", "nx", "ny", "nz",
                                              "r", "g", "b", "i",  "-"};
  return names;
}

// Splits off the next token; separators are spaces, tabs, '\r', ',' and ';'.
std::string_view next_field(std::string_view& line) {
  auto sep = [](char c) { return c == ' ' || c == '\t' || c == '\r' || c == ',' || c == ';'; };
  std::size_t b = 0;
  while (b < line.size() && sep(line[b])) ++b;
  std::size_t e = b;
  while (e < line.size() && !sep(line[e])) ++e;
  std::string_view tok = line.substr(b, e - b);
  line.remove_prefix(e);
  return tok;
}

std::string lower(std::string_view s) {
  std::string r(s);
  for (auto& c : r) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return r;
}

// A header name (CloudCompare's or PCL-like) -> one of known_names(); "-" when unknown.
std::string map_header_name(std::string_view raw) {
  const std::string n = lower(raw);
  if (n == "x" || n == "y" || n == "z" || n == "nx" || n == "ny" || n == "nz" || n == "r" ||
      n == "g" || n == "b" || n == "i")
    return n;
  if (n == "normal_x") return "nx";
  if (n == "normal_y") return "ny";
  if (n == "normal_z") return "nz";
  if (n == "red") return "r";
  if (n == "green") return "g";
  if (n == "blue") return "b";
  if (n == "intensity" || n == "scalar_intensity") return "i";
  return "-";
}

// Checks a column list (from the option or a header): every name known, x y z present, no
// name twice (but '-'), normals and colours complete. Returns "" or what is wrong.
std::string check_columns(const std::vector<std::string>& cols) {
  if (cols.empty()) return "no columns";
  if (cols.size() > kMaxColumns) return "more than 64 columns";
  for (const auto& c : cols) {
    if (std::find(known_names().begin(), known_names().end(), c) == known_names().end())
      return "unknown column \"" + c + "\" (known: x y z nx ny nz r g b i, '-' = skip)";
    if (c != "-" && std::count(cols.begin(), cols.end(), c) > 1)
      return "column \"" + c + "\" given twice";
  }
  auto has = [&](const char* n) { return std::find(cols.begin(), cols.end(), n) != cols.end(); };
  if (!has("x") || !has("y") || !has("z")) return "x, y and z are required";
  const int normals = has("nx") + has("ny") + has("nz");
  if (normals != 0 && normals != 3) return "give all of nx, ny, nz or none";
  const int colours = has("r") + has("g") + has("b");
  if (colours != 0 && colours != 3) return "give all of r, g, b or none";
  return "";
}

bool unit_or_zero(double a, double b, double c) {
  const double n2 = a * a + b * b + c * c;
  return n2 == 0 || std::abs(n2 - 1.0) < 0.02;
}

bool byte_colour(double a, double b, double c) {
  for (double v : {a, b, c})
    if (!(v >= 0 && v <= 255 && v == std::floor(v))) return false;
  return true;
}

bool unit_colour(double a, double b, double c) {
  for (double v : {a, b, c})
    if (!(v >= 0 && v <= 1)) return false;
  return true;
}

std::vector<std::string> names(std::initializer_list<const char*> l) {
  return std::vector<std::string>(l.begin(), l.end());
}

std::string join(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& x : v) s += (s.empty() ? "" : " ") + x;
  return s;
}

}  // namespace

std::vector<std::string> parse_xyz_columns(const std::string& text) {
  std::vector<std::string> cols;
  std::string_view rest(text);
  for (auto t = next_field(rest); !t.empty(); t = next_field(rest)) cols.push_back(lower(t));
  const std::string problem = check_columns(cols);
  if (!problem.empty())
    throw OptionError("--xyz-columns \"" + text + "\": " + problem + "; e.g. x,y,z,r,g,b");
  return cols;
}

PointCloud read_xyz(const std::filesystem::path& path, ReadReport* report,
                    const XyzOptions& options) {
  const std::string file = path.string();
  const std::string bytes = io_detail::read_file_bytes(path);
  const std::string_view all(bytes);
  std::vector<std::string> cols = options.columns;
  std::string how = cols.empty() ? "" : "as given";
  std::vector<std::string> warnings;
  if (!cols.empty()) {
    const std::string problem = check_columns(cols);
    if (!problem.empty()) throw OptionError("xyz columns: " + problem);
  }
  std::vector<double> values;  // every data line's values, row after row
  std::vector<std::uint64_t> lines;
  std::size_t count_first = 0, pos = 0;
  std::uint64_t line = 0;
  bool first = true;
  double v[kMaxColumns];
  while (pos < all.size()) {
    std::size_t e = all.find('\n', pos);
    if (e == std::string_view::npos) e = all.size();
    std::string_view l = all.substr(pos, e - pos);
    pos = e + 1;
    ++line;
    const bool slash_header = l.substr(0, 2) == "//";
    if (slash_header) l.remove_prefix(2);
    if (const auto hash = l.find('#'); hash != std::string_view::npos) l = l.substr(0, hash);
    std::string_view probe = l;
    const std::string_view first_token = next_field(probe);
    if (first_token.empty()) continue;
    if (first && (slash_header || !io_detail::parse_double(first_token))) {
      // A header line of column names.
      std::vector<std::string> header;
      std::string_view rest = l;
      for (auto t = next_field(rest); !t.empty(); t = next_field(rest)) {
        if (io_detail::parse_double(t))
          throw InputError(file, line_place(line),
                           "a header line mixes names and numbers (" + io_detail::quote(t) + ")");
        header.push_back(map_header_name(t));
        if (header.back() == "-")
          warnings.push_back(file + ": " + line_place(line) + ": column \"" + std::string(t) +
                             "\" is not read (known: x y z nx ny nz r g b i)");
      }
      if (cols.empty()) {
        const std::string problem = check_columns(header);
        if (!problem.empty())
          throw InputError(file, line_place(line),
                           "header line: " + problem + "; give --xyz-columns");
        cols = header;
        how = "from the header line";
      }
      first = false;
      continue;
    }
    std::size_t count = 0;
    for (auto t = next_field(l); !t.empty(); t = next_field(l)) {
      if (count >= kMaxColumns)
        throw InputError(file, line_place(line), "more than 64 values on a line");
      const auto d = io_detail::parse_double(t);
      if (!d)
        throw InputError(file, line_place(line),
                         "value " + std::to_string(count + 1) + ": expected a number, found " +
                             io_detail::quote(t));
      v[count++] = *d;
    }
    if (count_first == 0) {
      count_first = count;
      if (!cols.empty() && cols.size() != count)
        throw InputError(file, line_place(line),
                         "expected " + std::to_string(cols.size()) + " values (" + join(cols) +
                             "), found " + std::to_string(count));
    } else if (count != count_first) {
      throw InputError(file, line_place(line),
                       "expected " + std::to_string(count_first) +
                           " numbers like the first data line, found " + std::to_string(count));
    }
    first = false;
    values.insert(values.end(), v, v + count);
    lines.push_back(line);
  }
  const std::size_t rows = lines.size();
  if (rows == 0) throw InputError(file, "", "no points (the file is empty or holds only comments)");
  const std::size_t n = count_first;
  auto at = [&](std::size_t row, std::size_t col) { return values[row * n + col]; };

  if (cols.empty()) {
    how = "guessed from " + std::to_string(n) + " values per line";
    auto all_rows = [&](std::size_t c0, auto pred) {
      for (std::size_t r = 0; r < rows; ++r)
        if (!pred(at(r, c0), at(r, c0 + 1), at(r, c0 + 2))) return false;
      return true;
    };
    auto colour_like = [&](std::size_t c0) {
      return all_rows(c0, byte_colour) ||
             (all_rows(c0, unit_colour) && !all_rows(c0, unit_or_zero));
    };
    const std::string ask =
        " values per line cannot be told apart; give the columns, e.g. --xyz-columns "
        "x,y,z,r,g,b";
    if (n == 3) {
      cols = names({"x", "y", "z"});
    } else if (n == 4) {
      cols = names({"x", "y", "z", "i"});
    } else if (n == 6) {
      // Unit triples win: 0/1 integer triples are far more often axis normals than primaries.
      if (all_rows(3, unit_or_zero))
        cols = names({"x", "y", "z", "nx", "ny", "nz"});
      else if (colour_like(3))
        cols = names({"x", "y", "z", "r", "g", "b"});
      else
        throw InputError(file, line_place(lines.front()),
                         "columns 4-6 are neither unit normals nor colours: 6" + ask);
    } else if (n == 7 && colour_like(3)) {
      cols = names({"x", "y", "z", "r", "g", "b", "i"});
    } else if (n == 9 && all_rows(6, unit_or_zero) && colour_like(3) &&
               !all_rows(3, unit_or_zero)) {
      cols = names({"x", "y", "z", "r", "g", "b", "nx", "ny", "nz"});
    } else if (n == 9 && all_rows(3, unit_or_zero) && colour_like(6) &&
               !all_rows(6, unit_or_zero)) {
      cols = names({"x", "y", "z", "nx", "ny", "nz", "r", "g", "b"});
    } else {
      throw InputError(file, line_place(lines.front()), std::to_string(n) + ask);
    }
  }

  auto index_of = [&](const char* name) -> int {
    const auto it = std::find(cols.begin(), cols.end(), name);
    return it == cols.end() ? -1 : static_cast<int>(it - cols.begin());
  };
  const int ix = index_of("x"), iy = index_of("y"), iz = index_of("z");
  const int inx = index_of("nx"), iny = index_of("ny"), inz = index_of("nz");
  const int ir = index_of("r"), ig = index_of("g"), ib = index_of("b");
  const int ii = index_of("i");
  const auto col = [](int c) { return static_cast<std::size_t>(c); };
  // Colours 0-1 when every colour value is within [0, 1] and one is fractional; else 0-255.
  double colour_scale = 1;
  if (ir >= 0) {
    bool unit = true, fractional = false;
    for (std::size_t r = 0; r < rows && unit; ++r)
      for (int c : {ir, ig, ib}) {
        const double x = at(r, col(c));
        if (!(x >= 0 && x <= 1)) unit = false;
        if (x != std::floor(x)) fractional = true;
      }
    if (unit && fractional) colour_scale = 255;
  }

  PointCloud cloud;
  std::size_t dropped = 0;
  for (std::size_t r = 0; r < rows; ++r) {
    const Eigen::Vector3d p(at(r, col(ix)), at(r, col(iy)), at(r, col(iz)));
    if (!p.allFinite()) {
      ++dropped;
      continue;
    }
    cloud.positions.push_back(p);
    if (inx >= 0)
      cloud.normals.emplace_back(static_cast<float>(at(r, col(inx))),
                                 static_cast<float>(at(r, col(iny))),
                                 static_cast<float>(at(r, col(inz))));
    if (ir >= 0) {
      std::array<std::uint8_t, 4> rgba{0, 0, 0, 255};
      int k = 0;
      for (int c : {ir, ig, ib}) {
        const double x = at(r, col(c)) * colour_scale;
        if (!(x >= 0 && x <= 255.5))
          throw InputError(file, line_place(lines[r]),
                           "colour value " + io_detail::format_double(at(r, col(c))) +
                               ": expected 0-255 (or 0-1)");
        rgba[static_cast<std::size_t>(k++)] =
            static_cast<std::uint8_t>(std::lround(std::min(x, 255.0)));
      }
      cloud.colors.push_back(rgba);
    }
    if (ii >= 0) cloud.intensities.push_back(static_cast<float>(at(r, col(ii))));
  }
  if (report) {
    report->format = "xyz";
    report->encoding = "ascii, columns " + how;
    report->declared_points = rows;
    report->fields = cols;
    for (auto& w : warnings) report->warnings.push_back(std::move(w));
    if (dropped > 0) {
      report->dropped_invalid += dropped;
      report->warnings.push_back(file + ": " + std::to_string(dropped) + " of " +
                                 std::to_string(rows) + " points dropped: non-finite x, y or z");
    }
  }
  return cloud;
}

void write_xyz(const std::filesystem::path& path, const PointCloud& cloud) {
  cloud.check_consistent();
  write_file_atomically(path, [&](std::ostream& os) {
    std::string buf;
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      const auto& p = cloud.positions[i];
      buf += io_detail::format_double(p.x()) + ' ' + io_detail::format_double(p.y()) + ' ' +
             io_detail::format_double(p.z());
      if (cloud.has_normals()) {
        const auto& n = cloud.normals[i];
        buf += ' ' + io_detail::format_float(n.x()) + ' ' + io_detail::format_float(n.y()) + ' ' +
               io_detail::format_float(n.z());
      }
      buf += '\n';
      if (buf.size() > (1u << 20)) {
        os << buf;
        buf.clear();
      }
    }
    os << buf;
  });
}

}  // namespace scanclean

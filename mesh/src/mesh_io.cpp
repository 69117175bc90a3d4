#include "scanclean/mesh/mesh_io.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>

#include "scanclean/core/atomic_file.h"
#include "scanclean/core/errors.h"

namespace scanclean {
namespace {

std::string lower(std::string s) {
  for (auto& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

bool fits_float(const std::vector<Eigen::Vector3d>& v) {
  if (v.empty()) return true;
  Eigen::AlignedBox3d box;
  for (const auto& p : v) box.extend(p);
  const double tol = 1e-6 * std::max(box.diagonal().norm(), 1e-300);
  for (const auto& p : v)
    for (int k = 0; k < 3; ++k)
      if (std::abs(static_cast<double>(static_cast<float>(p[k])) - p[k]) > tol) return false;
  return true;
}

template <class T>
void put(std::ostream& os, T value) {
  char b[sizeof(T)];
  std::memcpy(b, &value, sizeof(T));  // little-endian hosts only (as io's PLY writer)
  os.write(b, sizeof(T));
}

}  // namespace

bool is_mesh_output_path(const std::filesystem::path& path) {
  return lower(path.extension().string()) == ".ply";
}

void write_mesh_ply(const std::filesystem::path& path, const TriangleMesh& mesh,
                    const MeshWriteOptions& options) {
  if (!is_mesh_output_path(path))
    throw OptionError("mesh output \"" + path.string() + "\": expected a .ply file name");
  // Vertex renumbering (identity unless unreferenced vertices are dropped).
  std::vector<std::int64_t> new_index(mesh.vertices.size());
  std::vector<std::size_t> kept;
  if (options.drop_unreferenced) {
    std::vector<std::uint8_t> used(mesh.vertices.size(), 0);
    for (const auto& t : mesh.triangles)
      for (int k = 0; k < 3; ++k) used[static_cast<std::size_t>(t[k])] = 1;
    for (std::size_t i = 0; i < used.size(); ++i) {
      new_index[i] = used[i] ? static_cast<std::int64_t>(kept.size()) : -1;
      if (used[i]) kept.push_back(i);
    }
  } else {
    kept.resize(mesh.vertices.size());
    for (std::size_t i = 0; i < kept.size(); ++i) kept[i] = i, new_index[i] = std::int64_t(i);
  }
  std::vector<Eigen::Vector3d> verts;
  verts.reserve(kept.size());
  for (auto i : kept) verts.push_back(mesh.vertices[i]);
  const bool as_float = fits_float(verts);
  const bool ascii = options.encoding == PlyEncoding::kAscii;

  std::string header = "ply\nformat ";
  header += ascii ? "ascii 1.0\n" : "binary_little_endian 1.0\n";
  header += "comment written by scanclean (units: metres)\n";
  for (auto c : options.comments) {
    std::replace(c.begin(), c.end(), '\n', ' ');
    std::replace(c.begin(), c.end(), '\r', ' ');
    header += "comment " + c + "\n";
  }
  header += "element vertex " + std::to_string(verts.size()) + "\n";
  const char* type = as_float ? "float" : "double";
  for (const char* axis : {"x", "y", "z"})
    header += std::string("property ") + type + " " + axis + "\n";
  header += "element face " + std::to_string(mesh.triangles.size()) + "\n";
  header += "property list uchar int vertex_indices\nend_header\n";

  write_file_atomically(
      path,
      [&](std::ostream& os) {
        os.write(header.data(), static_cast<std::streamsize>(header.size()));
        if (ascii) {
          os.precision(as_float ? 9 : 17);
          for (const auto& p : verts) os << p.x() << ' ' << p.y() << ' ' << p.z() << '\n';
          for (const auto& t : mesh.triangles)
            os << "3 " << new_index[static_cast<std::size_t>(t[0])] << ' '
               << new_index[static_cast<std::size_t>(t[1])] << ' '
               << new_index[static_cast<std::size_t>(t[2])] << '\n';
        } else {
          for (const auto& p : verts)
            for (int k = 0; k < 3; ++k) {
              if (as_float)
                put(os, static_cast<float>(p[k]));
              else
                put(os, p[k]);
            }
          for (const auto& t : mesh.triangles) {
            put(os, std::uint8_t{3});
            for (int k = 0; k < 3; ++k)
              put(os, static_cast<std::int32_t>(new_index[static_cast<std::size_t>(t[k])]));
          }
        }
        if (!os) throw IoError(path.string() + ": write failed");
      },
      !ascii);
}

std::optional<double> recorded_kernel_size(const std::filesystem::path& cloud_file) {
  if (lower(cloud_file.extension().string()) != ".ply") return std::nullopt;
  std::ifstream in(cloud_file, std::ios::binary);
  if (!in) return std::nullopt;
  std::string line;
  std::size_t read = 0;
  while (std::getline(in, line) && read < (1u << 16)) {
    read += line.size() + 1;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line == "end_header") break;
    std::istringstream words(line);
    std::string kw;
    words >> kw;
    if (kw != "comment" && kw != "obj_info") continue;
    std::vector<std::string> tokens;
    for (std::string token; words >> token;) tokens.push_back(token);
    for (std::size_t i = 0; i < tokens.size(); ++i) {
      // "h=0.0027", "h=2.7mm", "h: 0.0027 m", "filter_h 2.7 mm"
      std::string key = tokens[i], value;
      const auto sep = key.find_first_of("=:");
      std::size_t next = i + 1;
      if (sep != std::string::npos) {
        value = key.substr(sep + 1);
        key = key.substr(0, sep);
      }
      key = lower(key);
      if (key != "h" && key != "filter_h") continue;
      if (value.empty() && next < tokens.size()) value = tokens[next++];
      while (!value.empty() && (value.back() == ',' || value.back() == ';')) value.pop_back();
      char* end = nullptr;
      double h = std::strtod(value.c_str(), &end);
      if (value.empty() || end == value.c_str()) continue;
      std::string unit = end;
      if (unit.empty() && next < tokens.size()) {
        std::string t = tokens[next];
        while (!t.empty() && (t.back() == ',' || t.back() == ';')) t.pop_back();
        if (t == "m" || t == "mm") unit = t;
      }
      while (!unit.empty() && (unit.back() == ',' || unit.back() == ';')) unit.pop_back();
      if (unit == "mm")
        h *= 1e-3;
      else if (!unit.empty() && unit != "m")
        continue;
      if (std::isfinite(h) && h > 0) return h;
    }
  }
  return std::nullopt;
}

}  // namespace scanclean

#include "scanclean/io/xyz.h"

#include <string>
#include <string_view>

#include "file_bytes.h"
#include "scanclean/core/atomic_file.h"
#include "scanclean/core/errors.h"

namespace scanclean {

PointCloud read_xyz(const std::filesystem::path& path, ReadReport* report) {
  const std::string file = path.string();
  const std::string bytes = io_detail::read_file_bytes(path);
  const std::string_view all(bytes);
  PointCloud cloud;
  std::size_t columns = 0, pos = 0, dropped = 0, declared = 0;
  std::uint64_t line = 0;
  double v[6];
  while (pos < all.size()) {
    std::size_t e = all.find('\n', pos);
    if (e == std::string_view::npos) e = all.size();
    std::string_view l = all.substr(pos, e - pos);
    pos = e + 1;
    ++line;
    if (const auto hash = l.find('#'); hash != std::string_view::npos) l = l.substr(0, hash);
    std::size_t count = 0;
    for (auto t = io_detail::next_token(l); !t.empty(); t = io_detail::next_token(l)) {
      if (count < 6) {
        const auto d = io_detail::parse_double(t);
        if (!d)
          throw InputError(file, line_place(line),
                           "value " + std::to_string(count + 1) + ": expected a number, found " +
                               io_detail::quote(t));
        v[count] = *d;
      }
      ++count;
    }
    if (count == 0) continue;
    if (columns == 0) {
      if (count != 3 && count != 6)
        throw InputError(
            file, line_place(line),
            "expected 3 numbers (x y z) or 6 (x y z nx ny nz), found " + std::to_string(count));
      columns = count;
    } else if (count != columns) {
      throw InputError(file, line_place(line),
                       "expected " + std::to_string(columns) +
                           " numbers like the first data line, found " + std::to_string(count));
    }
    ++declared;
    const Eigen::Vector3d p(v[0], v[1], v[2]);
    if (!p.allFinite()) {
      ++dropped;
      continue;
    }
    cloud.positions.push_back(p);
    if (columns == 6) cloud.normals.emplace_back(float(v[3]), float(v[4]), float(v[5]));
  }
  if (report) {
    report->format = "xyz";
    report->encoding = "ascii";
    report->declared_points = declared;
    report->fields = columns == 6 ? std::vector<std::string>{"x", "y", "z", "nx", "ny", "nz"}
                                  : std::vector<std::string>{"x", "y", "z"};
    if (dropped > 0) {
      report->dropped_invalid += dropped;
      report->warnings.push_back(file + ": " + std::to_string(dropped) + " of " +
                                 std::to_string(declared) +
                                 " points dropped: non-finite x, y or z");
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

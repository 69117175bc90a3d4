#include "scanclean/io/stanford_conf.h"

#include <cmath>
#include <string>
#include <string_view>

#include "file_bytes.h"
#include "scanclean/core/errors.h"
#include "scanclean/io/point_cloud_io.h"
#include "scanclean/io/range_grid_normals.h"

namespace scanclean {

Eigen::Isometry3d conf_pose(const Eigen::Vector3d& t, const Eigen::Quaterniond& q) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  // Checked on bun.conf against bun_zipper.ply: the scans land on the mesh (median ~0.06 mm)
  // only with the conjugate rotation; R(q) itself leaves them tens of millimetres off.
  pose.linear() = q.normalized().conjugate().toRotationMatrix();
  pose.translation() = t;
  return pose;
}

ScanSession read_conf(const std::filesystem::path& conf, ReadReport* report) {
  const std::string file = conf.string();
  const std::string bytes = io_detail::read_file_bytes(conf);
  const std::string_view all(bytes);
  const std::filesystem::path folder = conf.parent_path();
  ScanSession s;
  std::size_t pos = 0;
  std::uint64_t line = 0;
  while (pos < all.size()) {
    std::size_t e = all.find('\n', pos);
    if (e == std::string_view::npos) e = all.size();
    std::string_view l = all.substr(pos, e - pos);
    pos = e + 1;
    ++line;
    std::string_view rest = l;
    const std::string_view kw = io_detail::next_token(rest);
    if (kw.empty() || kw.front() == '#') continue;
    if (kw == "camera") continue;
    if (kw == "mesh") {
      if (report)
        report->warnings.push_back(file + ": " + line_place(line) +
                                   ": 'mesh' entry ignored (only bmesh range scans are read)");
      continue;
    }
    if (kw != "bmesh") {
      if (report)
        report->warnings.push_back(file + ": " + line_place(line) + ": unknown line " +
                                   io_detail::quote(l) + " skipped");
      continue;
    }
    const std::string_view name = io_detail::next_token(rest);
    double v[7];
    for (int k = 0; k < 7; ++k) {
      const std::string_view t = io_detail::next_token(rest);
      const auto d = io_detail::parse_double(t);
      if (name.empty() || !d || !std::isfinite(*d))
        throw InputError(
            file, line_place(line),
            "expected 'bmesh <file> tx ty tz qx qy qz qw' with 7 finite numbers, found " +
                io_detail::quote(l));
      v[k] = *d;
    }
    if (!io_detail::next_token(rest).empty())
      throw InputError(
          file, line_place(line),
          "extra values after 'bmesh <file> tx ty tz qx qy qz qw': " + io_detail::quote(l));
    const Eigen::Quaterniond q(v[6], v[3], v[4], v[5]);
    if (q.norm() < 0.5 || q.norm() > 2.0)
      throw InputError(file, line_place(line),
                       "quaternion (qx qy qz qw) has norm " + std::to_string(q.norm()) +
                           "; expected a unit quaternion");
    s.files.push_back(folder / std::string(name));
    s.poses.push_back(conf_pose(Eigen::Vector3d(v[0], v[1], v[2]), q));
    s.lines.push_back(line);
  }
  if (s.files.empty())
    throw InputError(file, "", "no 'bmesh <file> tx ty tz qx qy qz qw' line; expected range scans");
  return s;
}

PointCloud read_and_merge_conf(const std::filesystem::path& conf, ReadReport* report,
                               const ConfOptions& options) {
  ReadReport local;
  ReadReport& rep = report ? *report : local;
  const ScanSession s = read_conf(conf, &rep);
  PointCloud merged;
  std::size_t used = 0;
  std::uint64_t declared = 0;
  for (std::size_t i = 0; i < s.files.size(); ++i) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(s.files[i], ec)) {
      const std::string what = "scan file " + s.files[i].string() + " does not exist";
      if (!options.skip_missing)
        throw InputError(conf.string(), line_place(s.lines[i]),
                         what + " (skip_missing / --skip-missing merges the scans that exist)");
      rep.warnings.push_back(conf.string() + ": " + line_place(s.lines[i]) + ": " + what +
                             "; skipped");
      continue;
    }
    ReadReport part_report;
    PointCloud part = read_point_cloud(s.files[i], &part_report);
    for (auto& w : part_report.warnings) rep.warnings.push_back(std::move(w));
    rep.dropped_invalid += part_report.dropped_invalid;
    declared += part_report.declared_points;
    if (options.scan_normals && !part.has_normals()) {
      if (part.grid.empty()) {
        rep.warnings.push_back(s.files[i].string() +
                               ": no range grid, so its points get no normals from the scanner");
      } else {
        // Stanford's range scans look along -z of their own frame: their surfaces face +z.
        RangeGridNormals gn = range_grid_normals(part, Eigen::Vector3d::UnitZ());
        if (10 * gn.facing < 9 * gn.with_normal)
          rep.warnings.push_back(
              s.files[i].string() + ": only " + std::to_string(gn.facing) + " of the " +
              std::to_string(gn.with_normal) +
              " normals of its range grid face +z, the scanner's side: a range scan seen from "
              "+z was expected, its normals' orientation may be wrong");
        part.normals = std::move(gn.normals);
      }
    }
    transform(part, s.poses[i]);
    part.grid = OrganizedGrid{};
    append(merged, part);
    ++used;
  }
  if (used == 0)
    throw InputError(conf.string(), "",
                     "none of the " + std::to_string(s.files.size()) + " scan files listed exists");
  rep.format = "conf";
  rep.encoding = std::to_string(used) + " of " + std::to_string(s.files.size()) + " scans";
  rep.declared_points = declared;
  return merged;
}

}  // namespace scanclean

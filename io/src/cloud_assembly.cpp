#include "cloud_assembly.h"

#include <algorithm>
#include <cmath>

#include "scanclean/core/errors.h"

namespace scanclean::io_detail {

namespace {

int find_column(const std::vector<Column>& cols, std::initializer_list<const char*> names) {
  for (const char* n : names)
    for (std::size_t i = 0; i < cols.size(); ++i)
      if (cols[i].name == n) return static_cast<int>(i);
  return -1;
}

}  // namespace

std::uint8_t to_colour_byte(double v, bool floating) {
  if (std::isnan(v)) return 0;
  if (floating) v *= 255.0;
  return static_cast<std::uint8_t>(std::clamp(std::lround(v), 0L, 255L));
}

PointCloud assemble_cloud(std::vector<Column>& columns, std::size_t n, OrganizedGrid grid,
                          const std::string& file, const std::string& element_word,
                          InvalidPolicy policy, ReadReport* report,
                          const std::function<std::string(std::size_t)>& place_of) {
  std::vector<bool> used(columns.size(), false);
  const int cx = find_column(columns, {"x"}), cy = find_column(columns, {"y"}),
            cz = find_column(columns, {"z"});
  if (cx < 0 || cy < 0 || cz < 0) {
    std::string found;
    for (const auto& c : columns) found += (found.empty() ? "" : " ") + c.name;
    throw InputError(file, "header",
                     std::string("the ") + element_word + " data have no " +
                         (cx < 0   ? "x"
                          : cy < 0 ? "y"
                                   : "z") +
                         " field; expected x, y and z (found: " + (found.empty() ? "none" : found) +
                         ")");
  }
  PointCloud cloud;
  cloud.positions.resize(n);
  for (std::size_t i = 0; i < n; ++i)
    cloud.positions[i] = {columns[cx].values[i], columns[cy].values[i], columns[cz].values[i]};
  used[cx] = used[cy] = used[cz] = true;

  int nx = find_column(columns, {"nx"}), ny = find_column(columns, {"ny"}),
      nz = find_column(columns, {"nz"});
  if (nx < 0 || ny < 0 || nz < 0) {
    nx = find_column(columns, {"normal_x"});
    ny = find_column(columns, {"normal_y"});
    nz = find_column(columns, {"normal_z"});
  }
  if (nx >= 0 && ny >= 0 && nz >= 0) {
    cloud.normals.resize(n);
    for (std::size_t i = 0; i < n; ++i)
      cloud.normals[i] =
          Eigen::Vector3d(columns[nx].values[i], columns[ny].values[i], columns[nz].values[i])
              .cast<float>();
    used[nx] = used[ny] = used[nz] = true;
  }
  if (int c = find_column(columns, {"confidence"}); c >= 0) {
    cloud.confidences.resize(n);
    for (std::size_t i = 0; i < n; ++i)
      cloud.confidences[i] = static_cast<float>(columns[c].values[i]);
    used[c] = true;
  }
  if (int c = find_column(columns, {"intensity"}); c >= 0) {
    cloud.intensities.resize(n);
    for (std::size_t i = 0; i < n; ++i)
      cloud.intensities[i] = static_cast<float>(columns[c].values[i]);
    used[c] = true;
  }
  int cr = find_column(columns, {"red"}), cg = find_column(columns, {"green"}),
      cb = find_column(columns, {"blue"}), ca = find_column(columns, {"alpha"});
  if (cr < 0 || cg < 0 || cb < 0) {
    cr = find_column(columns, {"diffuse_red"});
    cg = find_column(columns, {"diffuse_green"});
    cb = find_column(columns, {"diffuse_blue"});
    ca = find_column(columns, {"diffuse_alpha"});
  }
  if (cr >= 0 && cg >= 0 && cb >= 0) {
    cloud.colors.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      cloud.colors[i] = {to_colour_byte(columns[cr].values[i], columns[cr].floating),
                         to_colour_byte(columns[cg].values[i], columns[cg].floating),
                         to_colour_byte(columns[cb].values[i], columns[cb].floating),
                         ca >= 0 ? to_colour_byte(columns[ca].values[i], columns[ca].floating)
                                 : std::uint8_t{255}};
    }
    used[cr] = used[cg] = used[cb] = true;
    if (ca >= 0) used[ca] = true;
  }
  for (std::size_t c = 0; c < columns.size(); ++c) {
    if (used[c]) continue;
    if (cloud.find_attribute(columns[c].name)) {
      if (report)
        report->warnings.push_back(file + ": header: duplicate field '" + columns[c].name +
                                   "' ignored (the first one is kept)");
      continue;
    }
    cloud.attributes.push_back(
        Attribute{columns[c].name, columns[c].type, std::move(columns[c].values)});
  }
  if (!grid.empty()) cloud.grid = std::move(grid);

  std::vector<std::size_t> keep;
  std::size_t invalid = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (cloud.positions[i].allFinite()) continue;
    if (policy == InvalidPolicy::kReject)
      throw InputError(
          file, place_of(i),
          element_word + " " + std::to_string(i) +
              " has a non-finite coordinate (NaN or infinity); expected finite x, y, z");
    ++invalid;
  }
  if (invalid > 0) {
    keep.reserve(n - invalid);
    for (std::size_t i = 0; i < n; ++i)
      if (cloud.positions[i].allFinite()) keep.push_back(i);
    cloud = select(cloud, keep);
    if (report) {
      report->dropped_invalid += invalid;
      report->warnings.push_back(file + ": " + std::to_string(invalid) + " of " +
                                 std::to_string(n) + " " + element_word +
                                 "s dropped: non-finite x, y or z (NaN marks missing data)" +
                                 (cloud.grid.empty() ? "" : "; their grid cells are empty"));
    }
  }
  return cloud;
}

}  // namespace scanclean::io_detail

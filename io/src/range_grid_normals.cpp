#include "scanclean/io/range_grid_normals.h"

#include <algorithm>
#include <cstdint>

namespace scanclean {

namespace {

// The grid's normals, all turned to the side where most of them have facing(p, n) > 0.
template <class Facing>
RangeGridNormals grid_normals(const PointCloud& scan, const RangeGridNormalOptions& options,
                              Facing facing_of) {
  RangeGridNormals out;
  out.normals.assign(scan.size(), Eigen::Vector3f::Zero());
  const OrganizedGrid& g = scan.grid;
  const int s = options.stencil;
  if (g.empty() || s < 1 || g.rows <= 2 * s || g.cols <= 2 * s) return out;
  auto point = [&](std::int32_t k) -> const Eigen::Vector3d& {
    return scan.positions[static_cast<std::size_t>(k)];
  };
  // The grid step: the median distance between row neighbours.
  std::vector<double> steps;
  for (int r = 0; r < g.rows; ++r)
    for (int c = 0; c + 1 < g.cols; ++c) {
      const std::int32_t a = g.at(r, c), b = g.at(r, c + 1);
      if (a >= 0 && b >= 0) steps.push_back((point(a) - point(b)).norm());
    }
  if (steps.empty()) return out;
  const auto mid = steps.begin() + static_cast<std::ptrdiff_t>(steps.size() / 2);
  std::nth_element(steps.begin(), mid, steps.end());
  const double reach = options.max_jump * s * *mid;
  const double reach2 = reach * reach;
  // The normals as the grid's handedness gives them, then all turned at once if most face away.
  std::size_t toward_count = 0, away_count = 0;
  for (int r = s; r + s < g.rows; ++r)
    for (int c = s; c + s < g.cols; ++c) {
      const std::int32_t k = g.at(r, c);
      if (k < 0) continue;
      const std::int32_t left = g.at(r, c - s), right = g.at(r, c + s), up = g.at(r - s, c),
                         down = g.at(r + s, c);
      if (left < 0 || right < 0 || up < 0 || down < 0) continue;
      const Eigen::Vector3d& p = point(k);
      bool near = true;
      for (const std::int32_t q : {left, right, up, down})
        near = near && (point(q) - p).squaredNorm() <= reach2;
      if (!near) continue;
      const Eigen::Vector3d n = (point(right) - point(left)).cross(point(down) - point(up));
      const double len = n.norm();
      if (!(len > 0)) continue;
      out.normals[static_cast<std::size_t>(k)] = (n / len).cast<float>();
      ++out.with_normal;
      const double facing = facing_of(p, n);
      toward_count += facing > 0 ? 1 : 0;
      away_count += facing < 0 ? 1 : 0;
    }
  out.facing = std::max(toward_count, away_count);
  if (away_count > toward_count)
    for (Eigen::Vector3f& n : out.normals) n = -n;
  return out;
}

}  // namespace

RangeGridNormals range_grid_normals(const PointCloud& scan, const Eigen::Vector3d& toward,
                                    const RangeGridNormalOptions& options) {
  return grid_normals(scan, options, [&](const Eigen::Vector3d&, const Eigen::Vector3d& n) {
    return n.dot(toward);
  });
}

RangeGridNormals range_grid_normals_from_viewpoint(const PointCloud& scan,
                                                   const Eigen::Vector3d& viewpoint,
                                                   const RangeGridNormalOptions& options) {
  return grid_normals(scan, options, [&](const Eigen::Vector3d& p, const Eigen::Vector3d& n) {
    return n.dot(viewpoint - p);
  });
}

}  // namespace scanclean

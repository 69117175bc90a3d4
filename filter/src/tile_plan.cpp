#include "tile_plan.h"

#include <algorithm>
#include <cmath>
#include <numeric>

namespace scanclean::detail {
namespace {

// Sums of the histogram over boxes of cells, each in constant time (a 3D prefix sum).
class Prefix {
 public:
  Prefix(const TileGrid& g, const std::vector<std::uint64_t>& h) : d_(g.dims) {
    const std::int64_t X = d_[0] + 1, Y = d_[1] + 1, Z = d_[2] + 1;
    s_.assign(static_cast<std::size_t>(X * Y * Z), 0);
    for (std::int64_t z = 1; z < Z; ++z)
      for (std::int64_t y = 1; y < Y; ++y)
        for (std::int64_t x = 1; x < X; ++x)
          s_[at(x, y, z)] = h[g.flat({x - 1, y - 1, z - 1})] + s_[at(x - 1, y, z)] +
                            s_[at(x, y - 1, z)] + s_[at(x, y, z - 1)] - s_[at(x - 1, y - 1, z)] -
                            s_[at(x - 1, y, z - 1)] - s_[at(x, y - 1, z - 1)] +
                            s_[at(x - 1, y - 1, z - 1)];
  }
  // Points in cells [lo, hi) (clipped to the grid).
  std::uint64_t count(CellBox b) const {
    for (int a = 0; a < 3; ++a) {
      b[a] = std::clamp<std::int64_t>(b[a], 0, d_[a]);
      b[a + 3] = std::clamp<std::int64_t>(b[a + 3], 0, d_[a]);
      if (b[a + 3] <= b[a]) return 0;
    }
    const auto [x0, y0, z0, x1, y1, z1] = b;
    return s_[at(x1, y1, z1)] - s_[at(x0, y1, z1)] - s_[at(x1, y0, z1)] - s_[at(x1, y1, z0)] +
           s_[at(x0, y0, z1)] + s_[at(x0, y1, z0)] + s_[at(x1, y0, z0)] - s_[at(x0, y0, z0)];
  }

 private:
  std::size_t at(std::int64_t x, std::int64_t y, std::int64_t z) const {
    return static_cast<std::size_t>((z * (d_[1] + 1) + y) * (d_[0] + 1) + x);
  }
  std::array<std::int64_t, 3> d_;
  std::vector<std::uint64_t> s_;
};

}  // namespace

std::array<std::int64_t, 3> TileGrid::cell_of(const Eigen::Vector3d& p) const {
  std::array<std::int64_t, 3> c{};
  for (int a = 0; a < 3; ++a)
    c[a] = std::clamp<std::int64_t>(static_cast<std::int64_t>(std::floor((p[a] - lo[a]) / cell)), 0,
                                    dims[a] - 1);
  return c;
}

TileGrid occupancy_grid(const Eigen::AlignedBox3d& box) {
  TileGrid g;
  g.lo = box.min();
  const Eigen::Vector3d ext = box.diagonal().cwiseMax(0.0);
  const double emax = ext.maxCoeff();
  if (!(emax > 0)) return g;  // a single location: one cell
  const double vol = std::max(ext.x(), emax * 1e-6) * std::max(ext.y(), emax * 1e-6) *
                     std::max(ext.z(), emax * 1e-6);
  g.cell = std::max(emax / 256.0, std::cbrt(vol / 2.0e6));
  for (int a = 0; a < 3; ++a)
    g.dims[a] = std::max<std::int64_t>(1, static_cast<std::int64_t>(std::ceil(ext[a] / g.cell)));
  return g;
}

std::vector<std::size_t> largest_first(const TilePlan& plan) {
  std::vector<std::size_t> order(plan.tiles.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return plan.tiles[a].with_halo > plan.tiles[b].with_halo;
  });
  return order;
}

TilePlan plan_tiles(const TileGrid& grid, const std::vector<std::uint64_t>& hist, double halo,
                    std::uint64_t limit, int ranks) {
  TilePlan plan;
  plan.grid = grid;
  plan.halo_cells =
      std::max<std::int64_t>(1, static_cast<std::int64_t>(std::ceil(halo / grid.cell)));
  const Prefix prefix(grid, hist);
  auto grown = [&](CellBox b) {
    for (int a = 0; a < 3; ++a) {
      b[a] -= plan.halo_cells;
      b[a + 3] += plan.halo_cells;
    }
    return b;
  };
  // Recursive bisection, depth first: leaves in order are the tiles.
  std::vector<CellBox> stack{{0, 0, 0, grid.dims[0], grid.dims[1], grid.dims[2]}};
  while (!stack.empty()) {
    const auto b = stack.back();
    stack.pop_back();
    const std::uint64_t own = prefix.count(b);
    if (own == 0) continue;
    const std::uint64_t with_halo = prefix.count(grown(b));
    if (with_halo <= limit) {
      plan.cells.push_back(b);
      continue;
    }
    // The cut (any axis, at least one cell on each side) whose larger half, halo included,
    // holds the fewest points; none that helps (the halo dominates): the box stays one tile.
    int axis = -1;
    std::int64_t cut = 0;
    std::uint64_t best = with_halo - with_halo / 16;
    for (int a = 0; a < 3; ++a)
      for (std::int64_t c = b[a] + 1; c < b[a + 3]; ++c) {
        auto l = b, r = b;
        l[a + 3] = c;
        r[a] = c;
        const std::uint64_t worst = std::max(prefix.count(grown(l)), prefix.count(grown(r)));
        if (worst < best) {
          best = worst;
          axis = a;
          cut = c;
        }
      }
    if (axis < 0) {
      plan.cells.push_back(b);
      continue;
    }
    auto left = b, right = b;
    left[axis + 3] = cut;
    right[axis] = cut;
    stack.push_back(right);  // the left half is handled first
    stack.push_back(left);
  }
  plan.tile_of_cell.assign(grid.cells(), 0);
  for (std::size_t t = 0; t < plan.cells.size(); ++t) {
    const auto& b = plan.cells[t];
    TilePlanEntry e;
    e.box = Eigen::AlignedBox3d(grid.lo + grid.cell * Eigen::Vector3d(b[0], b[1], b[2]),
                                grid.lo + grid.cell * Eigen::Vector3d(b[3], b[4], b[5]));
    e.own_points = prefix.count(b);
    e.with_halo = prefix.count(grown(b));
    for (std::int64_t z = b[2]; z < b[5]; ++z)
      for (std::int64_t y = b[1]; y < b[4]; ++y)
        for (std::int64_t x = b[0]; x < b[3]; ++x)
          plan.tile_of_cell[grid.flat({x, y, z})] = static_cast<std::uint32_t>(t);
    plan.tiles.push_back(e);
  }
  // Ranks: the largest tiles first, each to the least loaded rank (deterministic).
  std::vector<std::uint64_t> load(static_cast<std::size_t>(std::max(1, ranks)), 0);
  for (std::size_t t : largest_first(plan)) {
    const auto r =
        static_cast<std::size_t>(std::min_element(load.begin(), load.end()) - load.begin());
    plan.tiles[t].rank = static_cast<int>(r);
    load[r] += plan.tiles[t].with_halo;
  }
  return plan;
}

HaloLookup::HaloLookup(const TilePlan& plan, const Eigen::AlignedBox3d& box, double halo)
    : plan_(plan), halo_(halo) {
  look_.lo = plan.grid.lo;
  const Eigen::Vector3d ext = box.diagonal().cwiseMax(0.0);
  look_.cell = std::max({halo, ext.maxCoeff() / 128.0, 1e-12});
  for (int a = 0; a < 3; ++a)
    look_.dims[a] =
        std::max<std::int64_t>(1, static_cast<std::int64_t>(std::ceil(ext[a] / look_.cell)));
  tiles_.resize(look_.cells());
  const Eigen::Vector3d h3 = Eigen::Vector3d::Constant(halo);
  for (std::size_t k = 0; k < plan.tiles.size(); ++k) {
    const auto& b = plan.tiles[k].box;
    const auto lo = look_.cell_of(b.min() - h3), hi = look_.cell_of(b.max() + h3);
    for (std::int64_t z = lo[2]; z <= hi[2]; ++z)
      for (std::int64_t y = lo[1]; y <= hi[1]; ++y)
        for (std::int64_t x = lo[0]; x <= hi[0]; ++x)
          tiles_[look_.flat({x, y, z})].push_back(static_cast<std::uint32_t>(k));
  }
}

void HaloLookup::tiles_of(const Eigen::Vector3d& p, std::vector<std::uint32_t>& hits) const {
  const std::uint32_t home = plan_.tile_of(p);
  hits.assign(1, home);
  for (std::uint32_t k : tiles_[look_.flat(look_.cell_of(p))]) {
    if (k == home) continue;
    const auto& b = plan_.tiles[k].box;
    const Eigen::Vector3d gap =
        (b.min() - p).cwiseMax(p - b.max()).cwiseMax(Eigen::Vector3d::Zero());
    if (gap.maxCoeff() <= halo_) hits.push_back(k);
  }
}

}  // namespace scanclean::detail

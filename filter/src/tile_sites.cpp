#include "tile_sites.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "neighbor_index.h"
#include "tile_exchange.h"

namespace scanclean::detail {

std::uint64_t SiteGrid::code(const Eigen::Vector3f& p) const {
  std::int32_t c[3];
  for (int a = 0; a < 3; ++a) {
    const float f = std::floor((p[a] - lo[a]) * inv_cell);
    c[a] = static_cast<std::int32_t>(std::clamp(f, 0.0f, static_cast<float>(dims[a] - 1)));
  }
  return morton(c[0], c[1], c[2]);
}

SiteGrid site_grid(const Eigen::AlignedBox3d& box, const Eigen::Vector3d& origin, double cell) {
  SiteGrid g;
  // Rounding is monotonic: the smallest float coordinate is the float of the smallest one.
  const Eigen::Vector3f lo = (box.min() - origin).cast<float>();
  const Eigen::Vector3f hi = (box.max() - origin).cast<float>();
  const double max_extent = (hi - lo).cast<double>().maxCoeff();
  constexpr double kMaxCells = (1 << 21) - 2;
  if (max_extent / cell > kMaxCells) cell = max_extent / kMaxCells * (1 + 1e-6);
  g.lo = lo - Eigen::Vector3f::Constant(static_cast<float>(cell) * 0.5f);
  g.inv_cell = static_cast<float>(1.0 / cell);
  for (int a = 0; a < 3; ++a)
    g.dims[a] = std::min<std::int32_t>(
        static_cast<std::int32_t>(std::floor((hi[a] - g.lo[a]) * g.inv_cell)) + 2, (1 << 21) - 1);
  return g;
}

double kernel_site_cell(double h, double h0, double r_est) {
  if (r_est > 0) {
    double first = r_est * 1.6;
    if (!grid_serves(first, h0)) first = grid_cell_for(h0);
    if (grid_serves(first, h)) return first;
  }
  return grid_cell_for(h);
}

KernelSites::KernelSites(const TiledSource& src, std::array<std::uint64_t, 2> range,
                         std::size_t chunk, const TileComm& comm, const Eigen::AlignedBox3d& box,
                         double cell, std::uint64_t stride)
    : origin_(box.center()), grid_(site_grid(box, origin_, cell)), stride_(stride) {
  std::unordered_map<std::uint64_t, std::uint64_t> counts;
  stream_records(src, range[0], range[1], chunk,
                 [&](const PointCloud& c, const std::vector<std::uint64_t>&) {
                   for (const auto& p : c.positions)
                     ++counts[grid_.code((p - origin_).cast<float>())];
                 });
  std::vector<std::array<std::uint64_t, 2>> mine;  // code, count
  mine.reserve(counts.size());
  for (const auto& [code, n] : counts) mine.push_back({code, n});
  std::unordered_map<std::uint64_t, std::uint64_t>().swap(counts);
  MessageWriter msg;
  msg.put_vec(mine);
  std::vector<std::array<std::uint64_t, 2>>().swap(mine);
  std::vector<std::string> all = allgather(comm, msg.bytes);
  std::string().swap(msg.bytes);
  // Per cell: {points in it, of which in lower ranks' records}.
  for (std::size_t r = 0; r < all.size(); ++r) {
    MessageReader rd{all[r]};
    for (const auto& [code, n] : rd.get_vec<std::array<std::uint64_t, 2>>()) {
      auto& e = cells_[code];
      e[0] += n;
      if (static_cast<int>(r) < comm.rank) e[1] += n;
    }
    std::string().swap(all[r]);
  }
  // Then, cells in Morton order: {the whole cloud's points before this process's first point
  // of the cell, mod stride; 0 numbered}.
  std::vector<std::uint64_t> codes;
  codes.reserve(cells_.size());
  for (const auto& kv : cells_) codes.push_back(kv.first);
  std::sort(codes.begin(), codes.end());
  std::uint64_t before = 0;
  for (std::uint64_t code : codes) {
    auto& e = cells_[code];
    const std::uint64_t n = e[0];
    e = {(before + e[1]) % stride_, 0};
    before += n;
  }
}

bool KernelSites::next_is_site(const Eigen::Vector3d& p) {
  auto& e = cells_[grid_.code((p - origin_).cast<float>())];
  return (e[0] + e[1]++) % stride_ == 0;
}

}  // namespace scanclean::detail

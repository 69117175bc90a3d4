#include "kernel_sites.h"

#include <algorithm>
#include <cmath>

#include "parallel.h"

namespace scanclean::detail {

std::vector<std::uint8_t> local_kernel_strides(const NeighborIndex& index, std::size_t stride) {
  const std::size_t n = index.size();
  const std::size_t cells = index.cell_count();
  std::vector<std::uint8_t> out(n,
                                static_cast<std::uint8_t>(std::clamp<std::size_t>(stride, 1, 64)));
  if (cells == 0 || n == 0) return out;
  std::vector<std::uint32_t> block(cells, 0);
  parallel_each(cells, [&](std::size_t c) {
    std::uint32_t b = 0;
    index.for_each_adjacent_run(c, [&](std::uint32_t s, std::uint32_t e) { b += e - s; });
    block[c] = b;
  });
  // The median over the points: each point counts its cell's block.
  std::vector<std::uint32_t> per_point(n);
  for (std::size_t c = 0; c < cells; ++c)
    std::fill(per_point.begin() + index.cell_begin(c), per_point.begin() + index.cell_begin(c + 1),
              block[c]);
  std::vector<std::uint32_t> sorted = per_point;
  std::nth_element(sorted.begin(), sorted.begin() + n / 2, sorted.end());
  const double med = sorted[n / 2];
  if (!(med > 0)) return out;
  for (std::size_t s = 0; s < n; ++s) {
    const double f = std::max(1.0, std::floor(per_point[s] / (kDenserBy * med)));
    out[s] = static_cast<std::uint8_t>(std::min(64.0, static_cast<double>(stride) * f));
  }
  return out;
}

}  // namespace scanclean::detail

#include "kernel_sites.h"

#include <algorithm>
#include <cmath>

namespace scanclean::detail {

std::vector<std::uint8_t> local_kernel_strides(const NeighborIndex& index, std::size_t stride) {
  const std::size_t n = index.size();
  const std::size_t cells = index.cell_count();
  std::vector<std::uint8_t> out(n,
                                static_cast<std::uint8_t>(std::clamp<std::size_t>(stride, 1, 64)));
  if (cells == 0 || n == 0) return out;
  const std::vector<std::uint32_t> block = index.adjacent_counts();
  const double med = index.value_at_point_rank(block, n / 2);  // the median over the points
  if (!(med > 0)) return out;
  for (std::size_t c = 0; c < cells; ++c) {
    const double f = std::max(1.0, std::floor(block[c] / (kDenserBy * med)));
    std::fill(out.begin() + index.cell_begin(c), out.begin() + index.cell_begin(c + 1),
              static_cast<std::uint8_t>(std::min(64.0, static_cast<double>(stride) * f)));
  }
  return out;
}

}  // namespace scanclean::detail

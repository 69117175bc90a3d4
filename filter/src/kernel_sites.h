#pragma once
//! Internal: where the kernels go. The paper puts a kernel at every point; the automatic kernel
//! stride (FilterOptions::kernel_stride 0) puts one at every stride-th point when h holds many
//! more than K_h points everywhere. Range scans are denser near the sensor by the square of the
//! range: with one h for the whole scan, a surface at 1 m holds 10 times more points within h
//! than one at 3 m, and a kernel at every point there makes both the fits and the projection's
//! candidate lists 10 times longer than the kernels need. The local stride thins the kernels
//! where the points are denser than at the median point, in proportion.

#include <cstddef>
#include <cstdint>
#include <vector>

#include "neighbor_index.h"

namespace scanclean::detail {

//! Per point, in the index's slot order: the kernel stride where it lies, stride x f, f =
//! max(1, floor(B / (kDenserBy B_med))), at most 64. B is the number of points in the 27 grid
//! cells around the point's cell, B_med its median over the points. A point in slot s carries a
//! kernel when s is a multiple of its stride (a spatially even subsample, as the global
//! stride's), weighted x its stride. On evenly sampled surfaces B varies by less than a factor
//! of 2 (the surface's slant through the cells), so f = 1 and the kernels are the global
//! stride's.
constexpr double kDenserBy = 2.0;
std::vector<std::uint8_t> local_kernel_strides(const NeighborIndex& index, std::size_t stride);

}  // namespace scanclean::detail

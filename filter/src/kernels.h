#pragma once
//! Internal: the kernels phase (the paper's section 2, eqs. 2-4). A weighted PCA at every
//! kernel_stride-th point (in grid order: a spatially even subsample) gives each kernel its
//! centre, its floored inverse covariance and its normal; the kernels are then frozen and
//! indexed by centre for the projection.

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "fill_later.h"
#include "kernel_record.h"
#include "neighbor_index.h"
#include "point_set.h"
#include "scanclean/filter/filter_options.h"

namespace scanclean::detail {

//! The frozen kernels of one pass, in the slot order of their centre index.
struct KernelSet {
  std::unique_ptr<NeighborIndex> index;   //!< over the centres (float, relative to the origin)
  FillLaterVector<KernelRecord> records;  //!< one per slot of index
  FillLaterVector<KernelFitRecord> fits;  //!< one per slot, when kept (KernelParams::keep_fits)
  std::size_t fitted = 0;                 //!< points that got a kernel (including w = 0)
  std::size_t refitted = 0;               //!< kernels refitted on their own sheet (plane_refit.h)
  std::size_t split = 0;                  //!< kernels fitted on their own face of a crease
};

struct KernelParams {
  const FilterOptions* options = nullptr;
  bool oriented = false;     //!< sensor normals select the neighbours (kernel_fit.h)
  double cell = 0;           //!< grid cell of the point index (ScaleChoice::h_grid)
  double kernel_cell = 0;    //!< of the centre index (ScaleChoice::h_grid_kernels; 0: cell)
  double gather_factor = 1;  //!< the projection's candidate radius / h (candidate_radius)
  std::size_t stride = 1;    //!< a kernel at every stride-th point, weight x stride
  bool keep_fits = false;    //!< keep the fits for the off-surface test's downdate
  //! When set: per point of d, its own kernel's support (chi-weighted neighbour count, itself
  //! left out); -1 where it has no kernel.
  std::vector<float>* support = nullptr;
  //! The own-plane refit (plane_refit.h): the cloud's noise sigma (0 = no refit).
  double noise_sigma = 0;
  //! When set (one per point of d): kernels at the points with a nonzero entry instead of at
  //! every stride-th, still weighted x stride. The tiled filter passes the whole cloud's
  //! subsample this way (kKernelSitesAttribute).
  const std::vector<std::uint8_t>* sites = nullptr;
  //! When set (one per point of d, and no sites): each point's own kernel stride (kernel_sites.h)
  //! instead of `stride`: a kernel at the points whose index in d is a multiple of it, weighted
  //! x it.
  const std::vector<std::uint8_t>* strides = nullptr;
};

//! The input attribute (0/1 per point) by which the tiled filter names the points that carry a
//! kernel in the in-memory run of the whole cloud (KernelParams::sites); never in an output. The
//! name holds spaces, which no PLY or PCD field name can: a file cannot set it.
inline constexpr const char* kKernelSitesAttribute = "scanclean tile kernel site";

//! How the point index passed to build_kernels numbers the points of d.
enum class PointIndexIds {
  kSlots,  //!< d is in the index's slot order (slot s is point s of d)
  kIds,    //!< the index's original indices are d's indices
};

//! Builds the kernels of the points of d. `point_index` holds d's points (float) and is released
//! when the fits are done (memory). `nref` receives each point's kernel normal (zero where it has
//! no kernel).
KernelSet build_kernels(const PointSet& d, std::unique_ptr<NeighborIndex>& point_index,
                        PointIndexIds ids, const KernelParams& params,
                        std::vector<Eigen::Vector3f>& nref, const std::string& phase);

}  // namespace scanclean::detail

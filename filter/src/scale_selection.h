#pragma once
//! Internal: scale selection for the automatic h (the "scale test"). For a point, the
//! intersection-of-confidence- intervals rule (Lepski's method; Katkovnik's ICI rule) picks the
//! largest ball radius of a ladder at which a plane fit still agrees with the fits in all smaller
//! balls.
//!
//! At each radius r_k the least-squares plane of the neighbours within r_k (the point itself
//! left out) estimates where the surface passes the point: z_k, the point's signed distance to
//! that plane, with standard error s_k = sqrt(lambda_3 / n_k). Larger balls shrink s_k; on a
//! curved surface, or where another sheet comes into reach, they shift z_k (a plane's offset from
//! a sphere of radius R grows like r^2 / 4R). The point's radius is the largest r_k whose interval
//! [z_k - gamma s_k, z_k + gamma s_k] still meets every smaller radius' interval.

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "plane_refit.h"

namespace scanclean {
class NeighborIndex;
}

namespace scanclean::detail {

struct ScaleSelectionOptions {
  std::vector<double> radii;  //!< ascending ball radii (metres), at most 16
  double gamma = 3.0;         //!< interval half-width in standard errors
  int k_min = 8;              //!< a radius with fewer neighbours ends the ladder
  double sigma = 0;           //!< > 0: the noise sigma for the standard errors (else lambda_3)
  //! The crease test, with crease.creases() (FilterOptions::crease_spread with scale_regions):
  //! where a ball's interval leaves the smaller balls', split_crease (the kernels' crease split,
  //! on the ball's neighbours with their chi weights at its radius) is tried on that ball, then
  //! on each larger one, until one holds a sharp crease. The ladder is then run again on the
  //! neighbours on the point's side of that wedge (its separating plane), and where every ball
  //! passes there, the point takes the largest radius. A crease the kernels split is no reason
  //! for a smaller h: on the faces beside it a smaller h only leaves more noise.
  PlaneRefit crease;
};

//! The radius chosen for each point p[q] with q in `queries`; `creases` (optional) receives the
//! number of points whose radius the crease test raised. `index` holds the points of `p`
//! (its original indices are p's), in float, relative to the same origin. A point whose smallest
//! ball holds fewer than k_min neighbours gets radii.front(). Deterministic; parallel (TBB).
std::vector<double> select_scale(const std::vector<Eigen::Vector3d>& p, const NeighborIndex& index,
                                 const std::vector<std::size_t>& queries,
                                 const ScaleSelectionOptions& options,
                                 std::size_t* creases = nullptr);

//! The scale per region (FilterOptions::scale_regions), one per grid cell of `cells` (an index
//! over the cloud's points): the median of `radii` (one per sample, as select_scale returned
//! them) over the k samples nearest to the centroid of the cell's points (summed in slot order;
//! all samples when there are fewer; ties in distance broken by the sample's place; for an even
//! k the mean of the two middle radii), given to every point of the cell. Indexed by the points'
//! original indices. An index without a grid: per point. `samples` are the sample points
//! (float, relative to the same origin). Deterministic, parallel.
std::vector<float> region_scales(const NeighborIndex& cells, std::vector<Eigen::Vector3f> samples,
                                 const std::vector<double>& radii, std::size_t k);

}  // namespace scanclean::detail

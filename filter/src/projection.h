#pragma once
//! Internal: the projection phase (the paper's section 2, eqs. 6-10). Every point moves by the
//! mean-shift-like update onto a maximum of the likelihood L built from the frozen kernels; the
//! off-surface test (off_surface.h) runs first, at the point's input position.

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "kernels.h"
#include "point_set.h"
#include "scanclean/filter/filter_options.h"

namespace scanclean::detail {

//! What became of a point in the projection phase.
enum class ProjectionState : std::uint8_t {
  kConverged,     //!< projected; the step fell below the tolerance
  kNotConverged,  //!< projected; the iteration cap was reached
  kUnsupported,   //!< no kernel supported it (left at its input position)
  kOffSurface,    //!< dropped before the projection by the off-surface test
  kSparse,        //!< dropped before the projection: its own kernel's support is below tau
};

//! True for the states of points that were projected (converged or not).
inline bool projected(ProjectionState s) {
  return s == ProjectionState::kConverged || s == ProjectionState::kNotConverged;
}

//! Per point, in the order of the projected positions.
struct Projected {
  std::vector<float> L;                  //!< likelihood where the last step was taken (StepSums)
  std::vector<std::uint8_t> iterations;  //!< iterations done (at most 255)
  std::vector<ProjectionState> state;
  std::vector<Eigen::Vector3f> normal;  //!< n_bar at the end, oriented like the reference
};

//! A point's candidate kernels are those whose centres lie within candidate_radius(o) h of where
//! they were gathered; they are gathered again once the point has moved by more than
//! kRegatherMargin h from there. So the kernels within max(1, truncation_sigma / 3) h of the
//! point, the reach of the truncated kernels of a neighbourhood of radius h, are always among
//! them. A narrow margin keeps the lists short (every iteration evaluates every candidate); a
//! point that moves farther gathers again. Of those kernels, a gather keeps only the ones within
//! 1.01 truncation_sigma sigma_j + kRegatherMargin h (KernelRecord::kSigma): the others are
//! truncated wherever the point can be before it gathers again (e_j >= |x - c_j|^2 / sigma_j^2),
//! so they would add nothing. The off-surface test reads the same first gather: its kernels
//! decide whether the point is near the surface at all (the others have e_j > truncation_sigma^2
//! there), and only when none of them vouches for the point are the kernels up to the larger of
//! truncation_sigma and outlier_sigma gathered apart (on the 2.1M sphere of the speed suite the
//! first lists were 1.4 times as long when they held those).
constexpr double kRegatherMargin = 1.0 / 8;
double candidate_radius(const FilterOptions& o);

//! The step of the normal update (UpdateMode::kNormal) along the mean normal, given the normal
//! part mu of the mean-shift vector at this iterate, and at the previous one prev_mu with the
//! step prev_step taken from it (0 before the first). Near a maximum of L, mu is about c t at a
//! distance t from it along the normal, and the plain step mu leaves (1 - c) t: with c small
//! (a likelihood wide along the normal) the plain steps shrink slowly. The secant through the
//! two iterates estimates c as (prev_mu - mu) / prev_step and returns mu / c, at most
//! kMaxSecantFactor mu; where that slope is not positive (no maximum ahead along the normal, or
//! the first iterate), the plain step mu. After plain steps this is Aitken's extrapolation,
//! mu / (1 - r) with r = mu / prev_mu; it also damps oscillations (r < 0), where the step is
//! shorter than mu.
constexpr double kMaxSecantFactor = 5;
double normal_step(double mu, double prev_mu, double prev_step);

//! Projects every point x[i] of d (in place), with kernels ks. `nref` holds each point's own
//! kernel normal (zero if none): the reference orientation where d has no sensor normal.
//! `sparse[i]` != 0 drops point i before the projection (state kSparse). With
//! `off_surface_test`, and when ks kept its fits, the off-surface test runs first
//! (FilterOptions::outlier_sigma).
void project_all(const PointSet& d, const KernelSet& ks, const std::vector<Eigen::Vector3f>& nref,
                 const FilterOptions& o, bool off_surface_test, bool oriented,
                 const std::vector<std::uint8_t>& sparse, std::vector<Eigen::Vector3d>& x,
                 Projected& out, const std::string& phase);

}  // namespace scanclean::detail

#pragma once
//! Internal: the off-surface test, run at each point's input position just before its
//! projection (FilterOptions::outlier_sigma).

#include <Eigen/Core>

#include "candidate_eval.h"
#include "kernels.h"

namespace scanclean::detail {

struct OffSurfaceTest {
  const KernelSet* kernels = nullptr;  //!< with their fits (KernelSet::fits)
  float threshold2 = 0;                //!< outlier_sigma^2 (a bound on e_j)
  double floor2 = 0;                   //!< eigen_floor^2
  bool oriented = false;               //!< sensor normals select a kernel's neighbours
};

//! True if some candidate kernel in `buf` puts the point at xl (relative to the buffer's
//! origin) within outlier_sigma standard deviations (e_j <= threshold2, slab test passed) once
//! both the point and the kernel's own centre point are taken out of that kernel's fit. Needs
//! the e_j of min_mahalanobis at xl in buf. Without leaving them out, a point off the surface
//! would vouch for itself through every kernel its weight has pulled towards it: its own (weight 1
//! at the centre), and, in pairs and clumps of outliers, each other's, which their centres (weight
//! 1 each) pull off the surface. The fit is downdated in closed form (weighted mean and covariance
//! without the points; a point is taken to be in the fit when it is within the trimming band of
//! the fitted plane) and floored as the kernels are. A kernel that puts the point within half the
//! threshold distance and in whose fit the two have under 10 % of the weight is taken as it is
//! (the downdate cannot move it past the threshold).
bool vouched(const OffSurfaceTest& test, CandidateBuffer& buf, const Eigen::Vector3d& xl,
             const Eigen::Vector3f& nref);

//! The Mahalanobis e = y^T S^-1 y of y under the covariance c with its eigenvalues floored at
//! floor2 (as the kernels' are), and y's component y0 along c's smallest eigenvector (sign
//! arbitrary). Without an eigenvalue below the floor, through c's inverse; else through its
//! eigen-decomposition.
void floored_mahalanobis(const Eigen::Matrix3d& c, const Eigen::Vector3d& y, double floor2,
                         double& e, double& y0);

//! Takes one sample (offset p from the centre point, chi weight t) out of a weighted fit with
//! mean offset m, covariance cov (m^2) and total weight w, in closed form: afterwards they are
//! the fit without it. Returns false, changing nothing, unless more than min_weight remains.
bool downdate_fit(Eigen::Vector3d& m, Eigen::Matrix3d& cov, double& w, const Eigen::Vector3d& p,
                  double t, double min_weight);

}  // namespace scanclean::detail

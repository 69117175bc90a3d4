#pragma once
//! Internal: the frozen kernel as the projection reads it (KernelRecord, one cache line), and
//! what the off-surface test needs to take points out of its fit (KernelFitRecord).

#include <Eigen/Core>
#include <cstddef>
#include <type_traits>

namespace scanclean::detail {

//! A kernel j of the likelihood (eq. 4): centre c_j, inverse covariance S_j^-1 (eigenvalues
//! floored), normal n_j, squared support radius h_j^2, weight w_j, and the largest standard
//! deviation sigma_j of S_j. Sixteen floats, read as one cache line and transposed eight at a
//! time into the candidate buffer (candidate_eval.h); the field order is that buffer's, up to
//! the weight.
struct alignas(64) KernelRecord {
  static constexpr std::size_t kFloats = 16;
  enum Field : std::size_t {
    kCx,
    kCy,
    kCz,  //!< centre (metres, relative to the cloud's local origin)
    kQ00,
    kQ11,
    kQ22,  //!< S^-1 diagonal (1/m^2)
    kQ01,
    kQ02,
    kQ12,  //!< 2 x S^-1 off-diagonal (1/m^2)
    kNx,
    kNy,
    kNz,  //!< kernel normal (unit; the sensor normal, else the PCA normal)
    kH2,  //!< h_j^2 (m^2)
    kW,   //!< w_j (times the kernel stride)
    //! sigma_j = sqrt of S_j's largest (floored) eigenvalue (m): as e_j(x) >= |x - c_j|^2 /
    //! sigma_j^2, the kernel is truncated (e_j >= t^2) farther than t sigma_j from its centre.
    kSigma,
  };
  //! Not initialised (a trivial type): the kernels phase fills its arrays in parallel instead of
  //! zeroing them first on one thread; set() writes every field.
  float f[kFloats];

  Eigen::Vector3f centre() const { return {f[kCx], f[kCy], f[kCz]}; }
  Eigen::Vector3f normal() const { return {f[kNx], f[kNy], f[kNz]}; }
  float h2() const { return f[kH2]; }
  float weight() const { return f[kW]; }
  float sigma() const { return f[kSigma]; }
  //! Sets every field; s_inv symmetric, the inverse of a covariance whose largest eigenvalue is
  //! sigma^2.
  void set(const Eigen::Vector3d& c, const Eigen::Matrix3d& s_inv, const Eigen::Vector3f& n,
           double h2, float w, double sigma) {
    for (int k = 0; k < 3; ++k) f[kCx + k] = static_cast<float>(c[k]);
    f[kQ00] = static_cast<float>(s_inv(0, 0));
    f[kQ11] = static_cast<float>(s_inv(1, 1));
    f[kQ22] = static_cast<float>(s_inv(2, 2));
    f[kQ01] = static_cast<float>(2 * s_inv(0, 1));
    f[kQ02] = static_cast<float>(2 * s_inv(0, 2));
    f[kQ12] = static_cast<float>(2 * s_inv(1, 2));
    for (int k = 0; k < 3; ++k) f[kNx + k] = n[k];
    f[kH2] = static_cast<float>(h2);
    f[kW] = w;
    f[kSigma] = static_cast<float>(sigma);
  }
};
static_assert(sizeof(KernelRecord) == 16 * sizeof(float), "one cache line per kernel");
static_assert(std::is_trivial_v<KernelRecord>);

//! A kernel's weighted fit as fitted (kernel_fit.h): m = c minus the centre point, the sum of
//! the chi weights, and the weighted covariance (m^2), for the leave-one-out downdate of the
//! off-surface test (off_surface.h).
struct KernelFitRecord {
  // Not initialised (a trivial type, as KernelRecord); set() writes every field.
  float m[3];
  float weight;
  float cov[6];  //!< 00 11 22 01 02 12

  Eigen::Vector3d offset() const { return {m[0], m[1], m[2]}; }
  Eigen::Matrix3d covariance() const {
    Eigen::Matrix3d c;
    c << cov[0], cov[3], cov[4], cov[3], cov[1], cov[5], cov[4], cov[5], cov[2];
    return c;
  }
  void set(const Eigen::Vector3d& offset, double w, const Eigen::Matrix3d& c) {
    for (int a = 0; a < 3; ++a) m[a] = static_cast<float>(offset[a]);
    weight = static_cast<float>(w);
    cov[0] = static_cast<float>(c(0, 0));
    cov[1] = static_cast<float>(c(1, 1));
    cov[2] = static_cast<float>(c(2, 2));
    cov[3] = static_cast<float>(c(0, 1));
    cov[4] = static_cast<float>(c(0, 2));
    cov[5] = static_cast<float>(c(1, 2));
  }
};

static_assert(std::is_trivial_v<KernelFitRecord>);

}  // namespace scanclean::detail

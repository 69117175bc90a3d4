#pragma once
//! Internal: the weighted PCA of a point's neighbourhood (the paper's eq. 2), made robust by
//! trimming. The kernels (kernels.h), the noise estimate of the automatic h (scale.h) and the
//! tests share it.

#include <Eigen/Core>
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <type_traits>
#include <vector>

#include "point_set.h"

namespace scanclean::detail {

struct KernelFit {
  Eigen::Vector3d c;       //!< weighted centroid
  Eigen::Vector3d lambda;  //!< ascending eigenvalues of C (m^2), not floored
  Eigen::Matrix3d e;       //!< eigenvectors (columns, matching lambda)
  Eigen::Vector3f n;       //!< kernel normal
  Eigen::Vector3d m;       //!< c minus the centre point
  Eigen::Matrix3d cov;     //!< weighted covariance (m^2), as fitted
  double weight = 0;       //!< sum of the chi weights of the neighbours in the fit
};

//! One neighbour of the fit: its offset from the centre point (metres) and its chi weight
//! t = (1 - r^2 / h^2)^4.
struct FitSample {
  double x, y, z, t;
};

//! The padding of the fit's sample arrays: the trimming's vector width.
constexpr std::size_t kFitLanes = 8;

//! The neighbours of a fit as a struct of arrays in float (offsets from the centre point in
//! metres, chi weights), the form the fit's loops read (with AVX2 the trimming eight at a time,
//! the sums four, widened to double). The entries from n to the next multiple of kFitLanes are
//! zeros (pad()).
struct FitSampleSet {
  std::vector<float> x, y, z, t;
  std::size_t n = 0;
  std::size_t capacity() const { return x.size() < kFitLanes ? 0 : x.size() - kFitLanes; }
  //! Room for cap samples (and the padding past them); keeps the first n.
  void reserve(std::size_t cap);
  void pad();
  void assign(const FitSample* samples, std::size_t count);  //!< rounded to float
  void append_to(std::vector<FitSample>& out) const;         //!< the n samples, in double
};

//! The unweighted moments of a fit's samples (every sample counted once): their count, mean
//! and covariance (offsets as the samples', metres). Summed in float, eight partial sums per
//! moment (sample k in partial k mod 8), combined in double.
struct SampleMoments {
  std::size_t n = 0;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
};
SampleMoments sample_moments(const FitSampleSet& samples);

//! The weighted sums of the fit (eq. 2) over the samples, in double (the samples widened):
//! sum t, sum t x, ..., sum t x x, ..., sum t x y, each product formed as (t x) y. Each sum is
//! four partial sums (sample k in partial k mod 4, in sample order), combined as
//! (0 + 1) + (2 + 3): independent additions for the vector path (4 doubles a lane, AVX2 when
//! the CPU has it), which does the very same operations per sum, so it gives the scalar loop's
//! results bit for bit.
struct FitSums {
  double s0 = 0, sx = 0, sy = 0, sz = 0;
  double sxx = 0, syy = 0, szz = 0;
  double sxy = 0, sxz = 0, syz = 0;
};
FitSums fit_sums(const FitSampleSet& samples);
//! The scalar reference of fit_sums (tests).
FitSums fit_sums_scalar(const FitSampleSet& samples);
//! Takes the terms of one sample, as fit_sums forms them, out of the sums.
inline void downdate_sums(FitSums& fs, float xf, float yf, float zf, float tf) {
  const double x = xf, y = yf, z = zf, t = tf;
  const double tx = t * x, ty = t * y, tz = t * z;
  fs.s0 -= t;
  fs.sx -= tx;
  fs.sy -= ty;
  fs.sz -= tz;
  fs.sxx -= tx * x;
  fs.syy -= ty * y;
  fs.szz -= tz * z;
  fs.sxy -= tx * y;
  fs.sxz -= tx * z;
  fs.syz -= ty * z;
}

//! The smallest eigenvalue of the symmetric c and a unit eigenvector of it, by Newton's method
//! on the characteristic polynomial from below (a few steps; no trigonometry), the vector from
//! the rows of c - lambda I. Returns false, and leaves the outputs alone, where that is slow or
//! ill-determined: the two smallest eigenvalues within a factor of about 2 of each other, or
//! within 1e-3 of c's largest entry; c zero or not finite.
bool smallest_eigenpair(const Eigen::Matrix3d& c, double& lambda, Eigen::Vector3d& v);

//! One trimming pass of the fit: the plane (unit normal n through m, offsets as the samples')
//! and the squared residual beyond which a sample is trimmed.
struct TrimPlane {
  double n[3], m[3];
  double limit2;
};
//! The plane of a trimming pass rounded to float, as the pass uses it (every instruction set).
struct TrimPlaneF {
  float nx, ny, nz, mx, my, mz, limit2;
  explicit TrimPlaneF(const TrimPlane& p)
      : nx(static_cast<float>(p.n[0])),
        ny(static_cast<float>(p.n[1])),
        nz(static_cast<float>(p.n[2])),
        mx(static_cast<float>(p.m[0])),
        my(static_cast<float>(p.m[1])),
        mz(static_cast<float>(p.m[2])),
        limit2(static_cast<float>(p.limit2)) {}
  bool trims(float x, float y, float z) const {
    const float r = nx * (x - mx) + ny * (y - my) + nz * (z - mz);
    return r * r > limit2;
  }
};
//! Keeps the samples whose residual r = (n_x (x - m_x) + n_y (y - m_y)) + n_z (z - m_z) has
//! !(r r > limit2), all in float (the plane rounded to float), moved down in order; takes the
//! others' terms (fit_sums' products, in double) out of `sums`, in sample order. Returns the
//! count kept (and sets samples.n to it, padded). Vectorised (16 samples at a time with
//! AVX-512, 8 with AVX2; fit_sample_loops.cpp), with the scalar loop's operations: its results
//! bit for bit on every processor.
std::size_t trim_samples(FitSampleSet& samples, const TrimPlane& plane, FitSums& sums);
//! The scalar reference of trim_samples (tests).
std::size_t trim_samples_scalar(FitSampleSet& samples, const TrimPlane& plane, FitSums& sums);

//! Appends to out the samples of the points p[js[k]], k < m, within h of `centre` (r2 < h2), in
//! order: offset p[j] - centre and r2 = (dx dx + dy dy) + dz dz in double, chi weight
//! t = 1 - r2 inv_h2 squared twice, each rounded to float. out needs room for m more. A vector
//! of points at a time (8 with AVX-512, 4 with AVX2; fit_sample_loops.cpp), with the scalar loop's
//! operations (no fused multiply-add): its results bit for bit on every processor. Returns the
//! count appended (out is not padded).
std::size_t make_samples(const Eigen::Vector3d* p, const std::uint32_t* js, std::size_t m,
                         const Eigen::Vector3d& centre, double h2, double inv_h2,
                         FitSampleSet& out);
//! The scalar reference of make_samples (tests).
std::size_t make_samples_scalar(const Eigen::Vector3d* p, const std::uint32_t* js, std::size_t m,
                                const Eigen::Vector3d& centre, double h2, double inv_h2,
                                FitSampleSet& out);

//! The weighted PCA of `samples` around the centre point `centre` (eq. 2), repeated without the
//! samples farther than 3 standard deviations from its plane (sqrt of lambda_3, at least the
//! eigenvalue floor eigen_floor h), at most twice. A near outlier would otherwise stretch the
//! kernels of the surface points around it towards itself (at 0.5 h from a kernel's centre and 5
//! sigma off its plane it adds about 40 % to the kernel's normal variance with K_h = 96), and they
//! would vouch for it. Fills everything but `n` (the caller orients it). Returns false if fewer
//! than k_min samples remain. Trims `samples` in place.
bool fit_samples(FitSampleSet& samples, const Eigen::Vector3d& centre, double h, int k_min,
                 double eigen_floor, KernelFit& out);
//! As above on samples given in double (rounded to float for the fit); `samples` becomes the
//! ones kept.
bool fit_samples(std::vector<FitSample>& samples, const Eigen::Vector3d& centre, double h,
                 int k_min, double eigen_floor, KernelFit& out);

//! The normal of a fitted kernel: the sensor normal vi when `use_dir` (an oriented fit at a point
//! with a sensor normal), the PCA normal (e.col(0)) otherwise; with `orients_only` the PCA
//! normal, turned to agree with vi when `use_dir`.
inline Eigen::Vector3f kernel_normal(const KernelFit& fit, bool use_dir, bool orients_only,
                                     const Eigen::Vector3f& vi) {
  if (use_dir && !orients_only) return vi;
  const Eigen::Vector3f n = fit.e.col(0).cast<float>().normalized();
  return use_dir && n.dot(vi) < 0 ? Eigen::Vector3f(-n) : n;
}

//! A superset of a point's neighbours as an array of indices into d, in the order a visitor
//! would give them: gather_samples and fit_kernel take it in place of a visitor, and make the
//! samples in one call where no neighbour needs a test of its own.
struct IndexSpan {
  const std::uint32_t* js = nullptr;
  std::size_t n = 0;
};

//! Appends to set the samples of the points d.p[js[k]], k < m, within h of pi (make_samples),
//! growing its room first (to at least twice what it holds then).
inline void append_samples(const PointSet& d, const std::uint32_t* js, std::size_t m,
                           const Eigen::Vector3d& pi, double h2, double inv_h2, FitSampleSet& set) {
  if (set.n + m > set.capacity()) set.reserve(std::max<std::size_t>(256, 2 * (set.n + m)));
  make_samples(d.p.data(), js, m, pi, h2, inv_h2, set);
}

//! gather_samples with a visitor.
template <class Visit>
void gather_visited(const PointSet& d, std::size_t i, double h, bool oriented, Visit&& visit,
                    FitSampleSet& set, Eigen::Vector3f* around = nullptr) {
  const Eigen::Vector3d pi = d.p[i];
  const double h2 = h * h, inv_h2 = 1.0 / h2;
  const bool use_dir = oriented && d.has_v(i);
  const Eigen::Vector3f vi = use_dir ? d.v[i] : Eigen::Vector3f::Zero();
  // The neighbours go to a buffer that only grows; their indices are made into samples a block
  // at a time (make_samples).
  set.n = 0;
  constexpr std::size_t kBlock = 64;
  std::uint32_t js[kBlock];
  std::size_t m = 0;
  auto flush = [&] {
    append_samples(d, js, m, pi, h2, inv_h2, set);
    m = 0;
  };
  const bool sum_normals = around && !d.v.empty();
  if (around) *around = Eigen::Vector3f::Zero();
  visit([&](std::size_t j) {
    // With sensor normals, only the neighbours facing the same way.
    if (use_dir && !(d.v[j].dot(vi) > 0.5f)) return;
    if (sum_normals) *around += d.v[j];
    js[m++] = static_cast<std::uint32_t>(j);
    if (m == kBlock) flush();
  });
  flush();
  set.pad();
}

//! The neighbours of point i of d within h as fit samples, in `set` (padded). `visit(g)` must
//! call g(j) for a superset of the neighbours (indices into d), or visit is an IndexSpan of
//! them. With `oriented` and a sensor normal at i, only neighbours whose sensor normals agree
//! with it (dot > 0.5). `around` (optional) receives the sum of the sensor normals of the
//! neighbours taken.
template <class Visit>
void gather_samples(const PointSet& d, std::size_t i, double h, bool oriented, Visit&& visit,
                    FitSampleSet& set, Eigen::Vector3f* around = nullptr) {
  if constexpr (std::is_same_v<std::decay_t<Visit>, IndexSpan>) {
    if (!(oriented && d.has_v(i)) && !(around && !d.v.empty())) {
      // Every neighbour is taken: the samples in one call, the same ones in the same order.
      const double h2 = h * h, inv_h2 = 1.0 / h2;
      if (around) *around = Eigen::Vector3f::Zero();
      set.n = 0;
      append_samples(d, visit.js, visit.n, d.p[i], h2, inv_h2, set);
      set.pad();
      return;
    }
    const IndexSpan span = visit;
    gather_visited(
        d, i, h, oriented,
        [span](auto&& g) {
          for (std::size_t k = 0; k < span.n; ++k) g(span.js[k]);
        },
        set, around);
  } else {
    gather_visited(d, i, h, oriented, visit, set, around);
  }
}

//! The robust weighted PCA of the neighbours of point i of d within h. `visit(g)` must call g(j)
//! for a superset of the neighbours (indices into d), or visit is an IndexSpan of them. With
//! `oriented` and a sensor normal at i, only neighbours whose sensor normals agree with it (dot >
//! 0.5) take part, and the kernel's normal is the sensor normal (d.v_orients_only: the PCA normal
//! turned to agree with it); otherwise it is the PCA normal, and with `oriented` in a cloud with
//! sensor normals (a point that has none of its own) turned to the side the sum of its neighbours'
//! sensor normals faces. Returns false if fewer than k_min neighbours remain. `untrimmed`
//! (optional) receives the neighbours as gathered, before trimming (for the own-plane refit,
//! plane_refit.h); `moments` (optional) their unweighted moments (for the crease split's first
//! test).
template <class Visit>
bool fit_kernel(const PointSet& d, std::size_t i, double h, int k_min, bool oriented,
                double eigen_floor, Visit&& visit, KernelFit& out,
                std::vector<FitSample>* untrimmed = nullptr, SampleMoments* moments = nullptr) {
  if (!(h > 0)) return false;
  const bool use_dir = oriented && d.has_v(i);
  const Eigen::Vector3f vi = use_dir ? d.v[i] : Eigen::Vector3f::Zero();
  thread_local FitSampleSet set;
  // A point without a sensor normal in a cloud that has them (a scan's border, a hole's edge):
  // its PCA normal takes the side its neighbours' sensor normals face.
  const bool orient_by_neighbours = oriented && !use_dir && !d.v.empty();
  Eigen::Vector3f around = Eigen::Vector3f::Zero();
  gather_samples(d, i, h, oriented, visit, set, orient_by_neighbours ? &around : nullptr);
  if (untrimmed) {
    untrimmed->clear();
    set.append_to(*untrimmed);
  }
  if (moments) *moments = sample_moments(set);
  if (!fit_samples(set, d.p[i], h, k_min, eigen_floor, out)) return false;
  out.n = kernel_normal(out, use_dir, d.v_orients_only, vi);
  if (orient_by_neighbours && out.n.dot(around) < 0) out.n = -out.n;
  return true;
}

}  // namespace scanclean::detail

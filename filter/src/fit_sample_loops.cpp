// The fit's loops over single samples (kernel_fit.h): make_samples (a fit's neighbours made into
// samples) and trim_samples (a trimming pass). Written once with Google Highway and compiled for
// every instruction set it targets on the build machine's architecture; the best one the
// processor has runs. Each lane does the scalar loop's operations on one sample, without
// contraction (filter/CMakeLists.txt); nothing is summed across lanes (the trimmed samples' terms
// are taken out of the sums one by one, in sample order), so every target gives the scalar
// loops' results bit for bit: make_samples_scalar's (AVX-512 takes 8 points at a time, AVX2 4)
// and trim_samples_scalar's (AVX-512 16 samples at a time, AVX2 8).

#include <algorithm>
#include <cstddef>
#include <cstdint>

#include "kernel_fit.h"

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "fit_sample_loops.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace scanclean::detail {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

// Stores one vector of samples (offsets and weights) at `at` in q's arrays.
template <class DF, class VF = hn::Vec<DF>>
HWY_INLINE void StoreSamples(DF d, FitSampleSet& q, std::size_t at, VF x, VF y, VF z, VF t) {
  hn::StoreU(x, d, q.x.data() + at);
  hn::StoreU(y, d, q.y.data() + at);
  hn::StoreU(z, d, q.z.data() + at);
  hn::StoreU(t, d, q.t.data() + at);
}

// A block of N points at a time: their coordinates gathered (a point is 3 doubles, so point j's
// x is double 3 j), offset from the centre, tested and weighted; a block with every point within
// h is stored with vector stores, the others point by point. The last m mod N points, by the
// scalar loop itself.
std::size_t MakeSamples(const Eigen::Vector3d* p, const std::uint32_t* js, std::size_t m,
                        const Eigen::Vector3d* centre, double h2, double inv_h2,
                        FitSampleSet* out) {
  const hn::ScalableTag<double> d;
  const hn::Rebind<std::uint32_t, decltype(d)> du32;
  const hn::RebindToUnsigned<decltype(d)> du64;
  const hn::RebindToSigned<decltype(d)> di64;
  const hn::Rebind<float, decltype(d)> df;
  const std::size_t N = hn::Lanes(d);
  const double* base = p->data();
  const auto cx = hn::Set(d, centre->x()), cy = hn::Set(d, centre->y());
  const auto cz = hn::Set(d, centre->z());
  const auto vh2 = hn::Set(d, h2), vinv = hn::Set(d, inv_h2), one = hn::Set(d, 1.0);
  float *ox = out->x.data(), *oy = out->y.data(), *oz = out->z.data(), *ot = out->t.data();
  const std::size_t before = out->n;
  std::size_t n = out->n, k = 0;
  HWY_ALIGN float lx[hn::MaxLanes(df)], ly[hn::MaxLanes(df)], lz[hn::MaxLanes(df)],
      lt[hn::MaxLanes(df)];
  HWY_ALIGN double lr2[hn::MaxLanes(d)];
  for (; k + N <= m; k += N) {
    const auto j = hn::PromoteTo(du64, hn::LoadU(du32, js + k));
    const auto at = hn::BitCast(di64, hn::Add(hn::ShiftLeft<1>(j), j));  // 3 j
    const auto dx = hn::Sub(hn::GatherIndex(d, base, at), cx);
    const auto dy = hn::Sub(hn::GatherIndex(d, base + 1, at), cy);
    const auto dz = hn::Sub(hn::GatherIndex(d, base + 2, at), cz);
    const auto r2 = hn::Add(hn::Add(hn::Mul(dx, dx), hn::Mul(dy, dy)), hn::Mul(dz, dz));
    const auto in = hn::Lt(r2, vh2);
    auto t = hn::Sub(one, hn::Mul(r2, vinv));
    t = hn::Mul(t, t);
    t = hn::Mul(t, t);
    const auto fx = hn::DemoteTo(df, dx), fy = hn::DemoteTo(df, dy);
    const auto fz = hn::DemoteTo(df, dz), ft = hn::DemoteTo(df, t);
    if (hn::AllTrue(d, in)) {
      StoreSamples(df, *out, n, fx, fy, fz, ft);
      n += N;
      continue;
    }
    hn::Store(fx, df, lx);
    hn::Store(fy, df, ly);
    hn::Store(fz, df, lz);
    hn::Store(ft, df, lt);
    hn::Store(r2, d, lr2);
    for (std::size_t l = 0; l < N; ++l) {
      ox[n] = lx[l];
      oy[n] = ly[l];
      oz[n] = lz[l];
      ot[n] = lt[l];
      n += lr2[l] < h2 ? 1 : 0;
    }
  }
  out->n = n;
  make_samples_scalar(p, js + k, m - k, *centre, h2, inv_h2, *out);
  return out->n - before;
}

// Trims blocks of Lanes(d) samples from k while k < end, block by block: a block with none
// trimmed is kept whole (moved down with vector stores once something before it was trimmed),
// the others sample by sample. Lanes past n (the padding) are neither trimmed nor kept.
template <class D>
HWY_INLINE void TrimBlocks(D d, FitSampleSet& q, const TrimPlaneF& p, std::size_t end,
                           std::size_t& k, std::size_t& kept, FitSums& fs) {
  const std::size_t N = hn::Lanes(d), n = q.n;
  float *px = q.x.data(), *py = q.y.data(), *pz = q.z.data(), *pt = q.t.data();
  const auto nx = hn::Set(d, p.nx), ny = hn::Set(d, p.ny), nz = hn::Set(d, p.nz);
  const auto mx = hn::Set(d, p.mx), my = hn::Set(d, p.my), mz = hn::Set(d, p.mz);
  const auto lim = hn::Set(d, p.limit2);
  std::uint8_t bits[(hn::MaxLanes(d) + 7) / 8];
  for (; k < end; k += N) {
    const auto x = hn::LoadU(d, px + k), y = hn::LoadU(d, py + k), z = hn::LoadU(d, pz + k);
    const auto r = hn::Add(hn::Add(hn::Mul(nx, hn::Sub(x, mx)), hn::Mul(ny, hn::Sub(y, my))),
                           hn::Mul(nz, hn::Sub(z, mz)));
    const auto out = hn::Gt(hn::Mul(r, r), lim);
    const std::size_t valid = std::min(N, n - k);
    if (valid == N && hn::AllFalse(d, out)) {
      if (kept != k) StoreSamples(d, q, kept, x, y, z, hn::LoadU(d, pt + k));
      kept += N;
      continue;
    }
    hn::StoreMaskBits(d, out, bits);
    for (std::size_t l = 0; l < valid; ++l) {
      const std::size_t s = k + l;
      if ((bits[l / 8] >> (l % 8)) & 1) {
        downdate_sums(fs, px[s], py[s], pz[s], pt[s]);
      } else {
        px[kept] = px[s];
        py[kept] = py[s];
        pz[kept] = pz[s];
        pt[kept] = pt[s];
        ++kept;
      }
    }
  }
}

// Whole vectors of samples first, then the rest in vectors of at most kFitLanes (the padding
// reaches the next multiple of kFitLanes past n).
std::size_t TrimSamples(FitSampleSet* q, const TrimPlane* plane, FitSums* fs) {
  const hn::ScalableTag<float> d;
  const hn::CappedTag<float, kFitLanes> d8;
  const std::size_t n = q->n, N = hn::Lanes(d);
  const TrimPlaneF p(*plane);
  std::size_t k = 0, kept = 0;
  TrimBlocks(d, *q, p, n / N * N, k, kept, *fs);
  TrimBlocks(d8, *q, p, n, k, kept, *fs);
  q->n = kept;
  q->pad();
  return kept;
}

}  // namespace HWY_NAMESPACE
}  // namespace scanclean::detail
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace scanclean::detail {

HWY_EXPORT(MakeSamples);
HWY_EXPORT(TrimSamples);

std::size_t make_samples(const Eigen::Vector3d* p, const std::uint32_t* js, std::size_t m,
                         const Eigen::Vector3d& centre, double h2, double inv_h2,
                         FitSampleSet& out) {
  return HWY_DYNAMIC_DISPATCH(MakeSamples)(p, js, m, &centre, h2, inv_h2, &out);
}

std::size_t trim_samples(FitSampleSet& samples, const TrimPlane& plane, FitSums& sums) {
  return HWY_DYNAMIC_DISPATCH(TrimSamples)(&samples, &plane, &sums);
}

}  // namespace scanclean::detail
#endif  // HWY_ONCE

// make_samples (kernel_fit.h): a fit's neighbours made into samples, written once with Google
// Highway and compiled for every instruction set it targets on the build machine's architecture;
// the best one the processor has runs. Each lane does the scalar loop's operations on one point,
// in double, without contraction (filter/CMakeLists.txt), and rounds them to float as it does;
// nothing is summed across lanes, so every target (AVX-512 takes 8 points at a time, AVX2 4)
// gives make_samples_scalar's samples bit for bit.

#include <cstddef>
#include <cstdint>

#include "kernel_fit.h"

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "make_samples.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

HWY_BEFORE_NAMESPACE();
namespace scanclean::detail {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

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
      hn::StoreU(fx, df, ox + n);
      hn::StoreU(fy, df, oy + n);
      hn::StoreU(fz, df, oz + n);
      hn::StoreU(ft, df, ot + n);
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

}  // namespace HWY_NAMESPACE
}  // namespace scanclean::detail
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace scanclean::detail {

HWY_EXPORT(MakeSamples);

std::size_t make_samples(const Eigen::Vector3d* p, const std::uint32_t* js, std::size_t m,
                         const Eigen::Vector3d& centre, double h2, double inv_h2,
                         FitSampleSet& out) {
  return HWY_DYNAMIC_DISPATCH(MakeSamples)(p, js, m, &centre, h2, inv_h2, &out);
}

}  // namespace scanclean::detail
#endif  // HWY_ONCE

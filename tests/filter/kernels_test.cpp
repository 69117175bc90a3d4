// The kernels phase (filter/src/kernels.h): every record against a weighted PCA of the point's
// neighbours found by brute force (the oracle), in the slot order of the centre index, and the
// kernel stride.

#include "../../filter/src/kernels.h"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>

#include "../../filter/src/kernel_fit.h"
#include "support/synthetic.h"

namespace scanclean::detail {
namespace {

// A noisy plane in the grid order of an index with cell h (as the filter stores its points).
struct Fixture {
  PointSet d;
  std::unique_ptr<NeighborIndex> index;
};

Fixture plane(double h) {
  const PointCloud c = test::noisy_plane(3000, 0.1, 0.0005, 31);
  std::vector<Eigen::Vector3f> pf;
  for (const auto& p : c.positions) pf.push_back(p.cast<float>());
  Fixture f;
  f.index = std::make_unique<NeighborIndex>(pf, h * 1.001);
  f.d.h = h;
  for (std::uint32_t i : f.index->order()) f.d.p.push_back(c.positions[i]);
  return f;
}

// A kernel at every point (the records moved into slot order in place) and at every 2nd (moved
// into a new array): the same checks.
void check_records_in_slot_order(std::size_t stride) {
  const double h = 0.008;
  Fixture f = plane(h);
  const PointSet& d = f.d;
  FilterOptions o;
  KernelParams prm;
  prm.options = &o;
  prm.cell = h;
  prm.stride = stride;
  prm.keep_fits = true;
  std::vector<Eigen::Vector3f> nref;
  const KernelSet ks = build_kernels(d, f.index, PointIndexIds::kSlots, prm, nref, "kernels");
  EXPECT_FALSE(f.index);  // released
  ASSERT_EQ(ks.records.size(), ks.index->size());
  ASSERT_EQ(ks.fits.size(), ks.records.size());
  // Every site of a dense plane gets a kernel.
  EXPECT_EQ(ks.fitted, (d.p.size() + stride - 1) / stride);
  // Centre k of the index's slot order is record k's centre.
  for (std::size_t s = 0; s < ks.records.size(); ++s)
    ASSERT_EQ(ks.index->slot_point(s), ks.records[s].centre()) << s;
  // Each kernel against a brute-force fit of its centre point's neighbours: find the point
  // whose fit has that centre.
  std::size_t checked = 0;
  for (std::size_t i = 0; i < d.p.size(); i += 37 * stride) {
    KernelFit fit;
    ASSERT_TRUE(fit_kernel(
        d, i, h, o.k_min, false, o.eigen_floor,
        [&](auto&& g) {
          for (std::size_t j = 0; j < d.p.size(); ++j) g(j);
        },
        fit));
    const Eigen::Vector3f c = fit.c.cast<float>();
    std::size_t found = ks.records.size();
    for (std::size_t s = 0; s < ks.records.size(); ++s)
      if (ks.records[s].centre() == c) found = s;
    ASSERT_LT(found, ks.records.size()) << "point " << i;
    const KernelRecord& r = ks.records[found];
    EXPECT_NEAR(r.h2(), h * h, 1e-12);
    EXPECT_EQ(r.weight(), static_cast<float>(stride));
    EXPECT_NEAR(std::abs(r.normal().dot(fit.e.col(0).cast<float>())), 1.0f, 1e-5f);
    // The inverse covariance, floored: S^-1 n = n / max(lambda_3, (eigen_floor h)^2).
    const double floor = std::pow(o.eigen_floor * h, 2);
    const Eigen::Vector3d n = fit.e.col(0);
    const Eigen::Vector3d sn(
        r.f[KernelRecord::kQ00] * n.x() + 0.5 * r.f[KernelRecord::kQ01] * n.y() +
            0.5 * r.f[KernelRecord::kQ02] * n.z(),
        0.5 * r.f[KernelRecord::kQ01] * n.x() + r.f[KernelRecord::kQ11] * n.y() +
            0.5 * r.f[KernelRecord::kQ12] * n.z(),
        0.5 * r.f[KernelRecord::kQ02] * n.x() + 0.5 * r.f[KernelRecord::kQ12] * n.y() +
            r.f[KernelRecord::kQ22] * n.z());
    const double expected = 1.0 / std::max(fit.lambda[0], floor);
    EXPECT_NEAR(sn.dot(n), expected, 1e-3 * expected);
    // The fit moved with its record.
    EXPECT_NEAR(ks.fits[found].weight, fit.weight, 1e-4 * fit.weight);
    EXPECT_LT((ks.fits[found].offset() - fit.m).norm(), 1e-6);
    ++checked;
  }
  EXPECT_GT(checked, 50 / stride);
}

TEST(KernelsTest, RecordsMatchABruteForceFitInSlotOrder) {
  check_records_in_slot_order(1);
  check_records_in_slot_order(2);
}

TEST(KernelsTest, StrideKeepsEveryStrideThPointWithItsWeightScaled) {
  const double h = 0.008;
  Fixture f = plane(h);
  FilterOptions o;
  KernelParams prm;
  prm.options = &o;
  prm.cell = h;
  prm.stride = 3;
  std::vector<Eigen::Vector3f> nref;
  const KernelSet ks = build_kernels(f.d, f.index, PointIndexIds::kSlots, prm, nref, "kernels");
  EXPECT_EQ(ks.records.size(), (f.d.p.size() + 2) / 3);
  EXPECT_TRUE(ks.fits.empty());
  for (const KernelRecord& r : ks.records) EXPECT_EQ(r.weight(), 3.0f);
  for (std::size_t i = 0; i < nref.size(); ++i)
    EXPECT_EQ(nref[i].squaredNorm() > 0, i % 3 == 0) << i;
}

TEST(KernelsTest, LocalStridesPlaceKernelsAtTheirMultiplesWeightedByThem) {
  const double h = 0.008;
  Fixture f = plane(h);
  FilterOptions o;
  KernelParams prm;
  prm.options = &o;
  prm.cell = h;
  std::vector<std::uint8_t> strides(f.d.p.size());
  for (std::size_t i = 0; i < strides.size(); ++i)
    strides[i] = static_cast<std::uint8_t>(1 + (i / 500) % 4);  // runs of 1, 2, 3, 4
  prm.strides = &strides;
  std::vector<Eigen::Vector3f> nref;
  const KernelSet ks = build_kernels(f.d, f.index, PointIndexIds::kSlots, prm, nref, "kernels");
  double weight = 0, expected = 0;
  std::size_t sites = 0;
  for (std::size_t i = 0; i < nref.size(); ++i) {
    const bool site = i % strides[i] == 0;
    EXPECT_EQ(nref[i].squaredNorm() > 0, site) << i;
    if (site) {
      expected += strides[i];
      ++sites;
    }
  }
  for (const KernelRecord& r : ks.records) weight += r.weight();
  EXPECT_EQ(ks.records.size(), sites);
  EXPECT_EQ(weight, expected);  // each kernel stands for its stride's points
  // The points stood for: about every point (the runs start at multiples of each stride).
  EXPECT_NEAR(weight, static_cast<double>(f.d.p.size()), 0.01 * static_cast<double>(f.d.p.size()));
}

}  // namespace
}  // namespace scanclean::detail

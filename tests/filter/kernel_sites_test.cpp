// The local kernel strides (filter/src/kernel_sites.h) against the density they follow: an
// evenly sampled surface keeps the global stride everywhere; a patch sampled 8 times denser
// than the rest (which holds most points, so the median) gets 4 times the stride inside, the
// factor floor(8 / kDenserBy).

#include "../../filter/src/kernel_sites.h"
#include "support/synthetic.h"

#include <gtest/gtest.h>

#include <random>

namespace scanclean::detail {
namespace {

// Points on the plane z = 0 over [0, 1] x [0, 0.5], uniformly at random, `per_m2` per square
// metre, and `dense_per_m2` inside the square [0.1, 0.3]^2 (if > 0).
std::vector<Eigen::Vector3f> plane(double per_m2, double dense_per_m2, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> ux(0.0f, 1.0f), uy(0.0f, 0.5f), ud(0.1f, 0.3f);
  std::vector<Eigen::Vector3f> p;
  const auto n = static_cast<std::size_t>(per_m2 * 0.5);
  for (std::size_t k = 0; k < n; ++k) {
    const float y = uy(rng), x = ux(rng);  // gcc's order (test::draw_point)
    const Eigen::Vector3f q(x, y, 0.0f);
    if (dense_per_m2 > 0 && q.x() > 0.1f && q.x() < 0.3f && q.y() > 0.1f && q.y() < 0.3f)
      continue;  // the patch gets its own density below
    p.push_back(q);
  }
  if (dense_per_m2 > 0) {
    const auto m = static_cast<std::size_t>(dense_per_m2 * 0.04);
    for (std::size_t k = 0; k < m; ++k) {
      const float y = ud(rng), x = ud(rng);
      p.emplace_back(x, y, 0.0f);
    }
  }
  return p;
}

bool inside(const Eigen::Vector3f& q, float lo, float hi) {
  return q.x() > lo && q.x() < hi && q.y() > lo && q.y() < hi;
}

TEST(KernelSitesTest, EvenSamplingKeepsTheGlobalStride) {
  const std::vector<Eigen::Vector3f> p = plane(400000, 0, 7);  // 200k points
  for (const double cell : {0.01, 0.017}) {
    const NeighborIndex index(p, cell);
    for (const std::size_t stride : {1, 2, 8}) {
      const std::vector<std::uint8_t> s = local_kernel_strides(index, stride);
      ASSERT_EQ(s.size(), p.size());
      for (std::size_t k = 0; k < s.size(); ++k)
        ASSERT_EQ(s[k], stride) << "slot " << k << ", cell " << cell;
    }
  }
}

TEST(KernelSitesTest, ADenserPatchGetsAProportionalStride) {
  // 160k points at 400k / m^2 outside the patch and 3.2M / m^2 (8 times) inside: 128k in the
  // patch, less than half of all, so the median density is the sparse part's.
  const std::vector<Eigen::Vector3f> p = plane(400000, 3200000, 11);
  const NeighborIndex index(p, 0.01);
  const std::vector<std::uint8_t> s = local_kernel_strides(index, 1);
  std::size_t dense = 0, sparse = 0;
  for (std::size_t slot = 0; slot < s.size(); ++slot) {
    const Eigen::Vector3f& q = index.slot_point(slot);
    if (inside(q, 0.13f, 0.27f)) {  // 3 cells inside the patch's edge: its blocks are all patch
      EXPECT_GE(s[slot], 3) << "slot " << slot;
      EXPECT_LE(s[slot], 4) << "slot " << slot;
      ++dense;
    } else if (!inside(q, 0.07f, 0.33f)) {
      EXPECT_EQ(s[slot], 1) << "slot " << slot;
      ++sparse;
    }
  }
  EXPECT_GT(dense, 50000u);
  EXPECT_GT(sparse, 50000u);
}

TEST(KernelSitesTest, TheStrideIsCappedAt64) {
  const std::vector<Eigen::Vector3f> p = plane(400000, 3200000, 11);
  const NeighborIndex index(p, 0.01);
  std::size_t capped = 0;
  for (const std::uint8_t v : local_kernel_strides(index, 40)) {
    EXPECT_TRUE(v == 40 || v == 64) << int{v};  // 40 x 1, or 40 x 2 and more, capped
    capped += v == 64 ? 1 : 0;
  }
  EXPECT_GT(capped, 50000u);
}

}  // namespace
}  // namespace scanclean::detail

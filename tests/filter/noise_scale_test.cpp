// The automatic h's noise fixed point and scale test (filter/src/noise_scale.h): where it starts
// for a K_h below kNoiseNeighbours, and what a small K_h did to a noisy sphere before it did.

#include "../../filter/src/noise_scale.h"

#include <gtest/gtest.h>

#include <cmath>

#include "scanclean/filter/robust_filter.h"
#include "support/synthetic.h"

namespace scanclean::detail {
namespace {

TEST(NoiseScaleTest, StartsAtH0FromKNoiseNeighboursUp) {
  EXPECT_EQ(noise_start_radius(0.01, 96), 0.01);
  EXPECT_EQ(noise_start_radius(0.01, 200), 0.01);
  EXPECT_DOUBLE_EQ(noise_start_radius(0.01, 24), 0.02);  // sqrt(96 / 24) = 2
  EXPECT_DOUBLE_EQ(noise_start_radius(0.03, 48), 0.03 * std::sqrt(2.0));
}

// 10,000 points on the unit sphere with noise sigma 0.01 and 0.02: with K_h = 32, h0 (about
// 0.11) is small against the noise band. Before the fixed point started from about 96
// neighbours, and before the scale test kept to balls that hold enough of them, h fell to h0 / 2
// (about 8 points a ball, fewer than k_min) and 60-98 % of the points were removed (K_h 32 and
// 16); on 50,000 points at 3.3 % noise the noise estimate was a third of sigma.
TEST(NoiseScaleTest, ASmallKhKeepsANoisySphere) {
  for (const double sigma : {0.01, 0.02}) {
    const PointCloud in = test::noisy_sphere(10000, 1.0, sigma, 6);
    for (const int k_h : {16, 32, 96}) {
      FilterOptions o;
      o.k_h = k_h;
      o.merge_eps = 0;
      const FilterResult r = robust_filter(in, o);
      SCOPED_TRACE("sigma " + std::to_string(sigma) + ", K_h " + std::to_string(k_h));
      EXPECT_GT(r.stats.points_out, 9700u);
      EXPECT_LT(r.stats.unsupported, 100u);
      EXPECT_NEAR(r.stats.noise_sigma, sigma, 0.15 * sigma);
      // h at least h0 and wide enough for the noise band (before: h0 / 2, under 6 sigma at 1 %).
      EXPECT_GE(r.stats.h, r.stats.h0);
      EXPECT_GT(r.stats.h, 6 * sigma);
      // The output lies on the sphere within the noise it removed.
      double sum = 0;
      for (const auto& p : r.cloud.positions) sum += (p.norm() - 1.0) * (p.norm() - 1.0);
      EXPECT_LT(std::sqrt(sum / static_cast<double>(r.cloud.size())), 0.35 * sigma);
    }
  }
}

}  // namespace
}  // namespace scanclean::detail

// The outputs phase's per-point attributes that describe what the filter did to each point:
// "displacement" (signed distance moved along the output normal).

#include <gtest/gtest.h>

#include <cmath>
#include <cstddef>

#include "scanclean/filter/robust_filter.h"
#include "support/synthetic.h"

namespace scanclean {
namespace {

TEST(FilterOutputsTest, DisplacementIsTheSignedMoveAlongTheNormal) {
  const double sigma = 0.004;
  PointCloud in = test::noisy_plane(3000, 1.0, sigma, 41);  // z ~ N(0, sigma)
  in.normals.clear();
  FilterOptions o;
  o.merge_eps = 0;  // one output point per kept input point
  o.threads = 2;
  const FilterResult r = robust_filter(in, o);
  ASSERT_GT(r.cloud.size(), 2900u);
  const Attribute* d = r.cloud.find_attribute("displacement");
  const Attribute* src = r.cloud.find_attribute("source_index");
  ASSERT_NE(d, nullptr);
  ASSERT_NE(src, nullptr);
  EXPECT_EQ(d->type, AttributeType::kFloat32);
  double sum2 = 0, err = 0;
  for (std::size_t k = 0; k < r.cloud.size(); ++k) {
    const auto i = static_cast<std::size_t>(src->values[k]);
    const Eigen::Vector3d n = r.cloud.normals[k].cast<double>();
    const double moved = (r.cloud.positions[k] - in.positions[i]).dot(n);
    ASSERT_NEAR(d->values[k], moved, 1e-6) << "point " << k;
    // The plane is z = 0: a point moves by -z along n = +z, by +z along n = -z.
    err += std::abs(d->values[k] + in.positions[i].z() * n.z());
    sum2 += d->values[k] * d->values[k];
  }
  const double rms = std::sqrt(sum2 / static_cast<double>(r.cloud.size()));
  EXPECT_GT(rms, 0.7 * sigma) << "the points were moved onto the plane by about the noise";
  EXPECT_LT(rms, 1.3 * sigma);
  EXPECT_LT(err / static_cast<double>(r.cloud.size()), 0.3 * sigma);
  // The dropped points carry no displacement (they are not moved).
  EXPECT_EQ(r.outliers.find_attribute("displacement"), nullptr);
}

}  // namespace
}  // namespace scanclean

namespace scanclean {
namespace {

TEST(FilterOutputsTest, MergedPointsAverageTheirColours) {
  // Every point of a plane twice, 1 micrometre apart, once red and once dark blue: each pair
  // merges (merge eps is a quarter of the spacing) into one point of the mean colour.
  const PointCloud base = test::noisy_plane(2000, 1.0, 0.002, 43);
  PointCloud in;
  for (std::size_t i = 0; i < base.size(); ++i) {
    in.positions.push_back(base.positions[i]);
    in.positions.push_back(base.positions[i] + Eigen::Vector3d(0, 0, 1e-6));
    in.colors.push_back({200, 0, 0, 255});
    in.colors.push_back({0, 0, 100, 255});
  }
  FilterOptions o;
  o.threads = 2;
  const FilterResult r = robust_filter(in, o);
  ASSERT_TRUE(r.cloud.has_colors());
  const Attribute* mc = r.cloud.find_attribute("merge_count");
  ASSERT_NE(mc, nullptr);
  std::size_t pairs = 0;
  for (std::size_t k = 0; k < r.cloud.size(); ++k) {
    if (mc->values[k] != 2) continue;
    ++pairs;
    const auto& c = r.cloud.colors[k];
    ASSERT_EQ(c[0], 100) << "point " << k;
    ASSERT_EQ(c[1], 0);
    ASSERT_EQ(c[2], 50);
    ASSERT_EQ(c[3], 255);
  }
  EXPECT_GT(pairs, 1500u);  // most pairs (a few points merge in threes or are removed)
  // The removed points keep their own colour.
  for (const auto& c : r.outliers.colors)
    EXPECT_TRUE((c == std::array<std::uint8_t, 4>{200, 0, 0, 255}) ||
                (c == std::array<std::uint8_t, 4>{0, 0, 100, 255}));
}

}  // namespace
}  // namespace scanclean

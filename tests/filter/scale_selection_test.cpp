// The scale selection of the automatic h (filter/src/scale_selection.h) against situations whose
// answer is known: a plane (no bias at any radius), spherical caps (bias growing as r^2 / R), two
// parallel sheets (the second one enters the balls at the gap), too few neighbours.

#include "../../filter/src/scale_selection.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "../../filter/src/neighbor_index.h"

namespace scanclean::detail {
namespace {

struct Cloud {
  std::vector<Eigen::Vector3d> p;
  std::vector<Eigen::Vector3f> f() const {
    std::vector<Eigen::Vector3f> out;
    for (const auto& q : p) out.push_back(q.cast<float>());
    return out;
  }
};

// n points uniform on the square [-0.5, 0.5]^2 at height z, Gaussian noise sigma along z.
void add_sheet(Cloud& c, std::size_t n, double z, double sigma, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-0.5, 0.5);
  std::normal_distribution<double> g(0.0, sigma);
  for (std::size_t i = 0; i < n; ++i) c.p.emplace_back(u(rng), u(rng), z + g(rng));
}

ScaleSelectionOptions ladder(double h, double sigma) {
  ScaleSelectionOptions o;
  for (int k = -4; k <= 2; ++k) o.radii.push_back(h * std::pow(2.0, k / 4.0));
  o.sigma = sigma;
  return o;
}

// Queries: the points within `inner` of the origin in x and y (away from open borders).
std::vector<std::size_t> central(const Cloud& c, double inner) {
  std::vector<std::size_t> q;
  for (std::size_t i = 0; i < c.p.size(); ++i)
    if (std::abs(c.p[i].x()) < inner && std::abs(c.p[i].y()) < inner) q.push_back(i);
  return q;
}

double median(std::vector<double> v) {
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

TEST(ScaleSelectionTest, APlaneTakesTheLargestRadius) {
  Cloud c;
  add_sheet(c, 20000, 0.0, 0.005, 61);  // seed 61
  const ScaleSelectionOptions o = ladder(0.05, 0.005);
  const NeighborIndex index(c.f(), o.radii.back() * 0.7);
  const auto q = central(c, 0.3);
  const std::vector<double> r = select_scale(c.p, index, q, o);
  std::size_t top = 0;
  for (double v : r) top += v == o.radii.back() ? 1 : 0;
  // A gamma = 3 interval misses by chance about 0.3 % of the time per comparison.
  EXPECT_GT(static_cast<double>(top), 0.9 * static_cast<double>(r.size()));
}

TEST(ScaleSelectionTest, MoreCurvedCapsTakeSmallerRadii) {
  // Caps of spheres of radius R over the same square: the plane of a ball of radius r sits
  // about r^2 / 4R inside the sphere, so the more curved the cap, the sooner the balls disagree.
  std::vector<double> med;
  for (double R : {100.0, 3.0, 0.6}) {
    Cloud c;
    add_sheet(c, 20000, 0.0, 0.001, 62);  // seed 62
    for (auto& q : c.p) q.z() += R - std::sqrt(R * R - q.x() * q.x() - q.y() * q.y());
    const ScaleSelectionOptions o = ladder(0.1, 0.001);
    const NeighborIndex index(c.f(), o.radii.back() * 0.7);
    med.push_back(median(select_scale(c.p, index, central(c, 0.3), o)));
    if (R == 100.0) {
      EXPECT_EQ(med.back(), o.radii.back());
    }
  }
  // Measured: 0.141 (the top), 0.084, 0.059.
  EXPECT_GT(med[0], med[1]);
  EXPECT_GT(med[1], med[2]);
}

TEST(ScaleSelectionTest, ASecondSheetStopsTheLadderAtTheGap) {
  // Sheets at z = 0 and z = 0.06: balls up to 0.06 see one sheet, larger ones both, whose plane
  // lies between them.
  Cloud c;
  add_sheet(c, 20000, 0.0, 0.002, 63);   // seed 63
  add_sheet(c, 20000, 0.06, 0.002, 64);  // seed 64
  const ScaleSelectionOptions o = ladder(0.07, 0.002);
  const NeighborIndex index(c.f(), o.radii.back() * 0.7);
  const std::vector<double> r = select_scale(c.p, index, central(c, 0.3), o);
  const double m = median(r);
  EXPECT_LE(m, 0.06);
  EXPECT_GE(m, 0.06 / std::pow(2.0, 0.5));  // at most two rungs below the gap
}

TEST(ScaleSelectionTest, TooFewNeighboursGiveTheSmallestRadius) {
  Cloud c;
  add_sheet(c, 50, 0.0, 0.001, 65);  // seed 65: about 0.3 neighbours in the smallest ball
  ScaleSelectionOptions o = ladder(0.01, 0.001);
  const NeighborIndex index(c.f(), o.radii.back() * 0.7);
  std::vector<std::size_t> q(c.p.size());
  for (std::size_t i = 0; i < q.size(); ++i) q[i] = i;
  for (double v : select_scale(c.p, index, q, o)) EXPECT_EQ(v, o.radii.front());
}

}  // namespace
}  // namespace scanclean::detail

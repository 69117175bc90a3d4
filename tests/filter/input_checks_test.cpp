// The filter's input checks (filter/src/input_checks.h): the first point refused, and why.
#include "../../filter/src/input_checks.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "support/synthetic.h"

namespace scanclean::detail {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

TEST(InputChecksTest, AValidCloudHasNoInvalidPoint) {
  PointCloud c = test::noisy_plane(50000, 1.0, 0.01, 21);  // seed 21
  c.confidences.assign(c.size(), 0.5f);
  c.confidences.front() = 0.0f;  // the interval's ends are valid
  c.confidences.back() = 1.0f;
  const InvalidPoint p = first_invalid_point(c, true);
  EXPECT_EQ(p.index, c.size());
  EXPECT_TRUE(p.what.empty());
}

TEST(InputChecksTest, TheFirstNonFinitePositionOfALargeCloud) {
  // Large enough that the search runs in parallel chunks: the first, not any, is reported.
  PointCloud c = test::noisy_plane(200000, 1.0, 0.01, 22);  // seed 22
  c.positions[150000].z() = std::numeric_limits<double>::infinity();
  c.positions[123457].x() = kNaN;
  c.positions[190000].y() = -std::numeric_limits<double>::infinity();
  const InvalidPoint p = first_invalid_point(c, false);
  EXPECT_EQ(p.index, 123457u);
  EXPECT_NE(p.what.find("non-finite coordinate"), std::string::npos) << p.what;
}

TEST(InputChecksTest, ConfidencesAreCheckedOnlyAsWeightsAndAfterPositions) {
  PointCloud c = test::noisy_plane(1000, 1.0, 0.01, 23);  // seed 23
  c.confidences.assign(c.size(), 0.5f);
  c.confidences[10] = 1.5f;
  c.confidences[20] = static_cast<float>(kNaN);
  EXPECT_EQ(first_invalid_point(c, false).index, c.size());  // not the weights: not checked
  const InvalidPoint w = first_invalid_point(c, true);
  EXPECT_EQ(w.index, 10u);
  EXPECT_EQ(w.what, "confidence 1.5 outside [0, 1]");
  c.confidences[10] = -0.25f;
  EXPECT_EQ(first_invalid_point(c, true).what, "confidence -0.25 outside [0, 1]");
  c.confidences[10] = 0.5f;
  EXPECT_EQ(first_invalid_point(c, true).index, 20u);  // NaN is outside too
  c.positions[900].y() = kNaN;  // a bad position is reported before any confidence
  const InvalidPoint both = first_invalid_point(c, true);
  EXPECT_EQ(both.index, 900u);
  EXPECT_NE(both.what.find("non-finite coordinate"), std::string::npos) << both.what;
}

}  // namespace
}  // namespace scanclean::detail

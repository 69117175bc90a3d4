#include "scanclean/core/range_frame.h"

#include <gtest/gtest.h>

#include "scanclean/core/errors.h"

namespace scanclean {
namespace {

TEST(IntrinsicsTest, FromFovMatchesOpenNIConverter) {
  // docs/SENSORS.md §4: hfov 1.0226 rad gives fx = 570.34 at 640 px; principal point at the centre.
  Intrinsics k = Intrinsics::from_fov(640, 480, 1.0226, 0.7966);
  EXPECT_NEAR(k.fx, 570.34, 0.01);
  EXPECT_DOUBLE_EQ(k.cx, 320.0);
  EXPECT_DOUBLE_EQ(k.cy, 240.0);
  EXPECT_FALSE(k.has_distortion());
  EXPECT_TRUE(k.valid());
}

TEST(IntrinsicsTest, RejectsNonsenseFov) {
  EXPECT_THROW(Intrinsics::from_fov(640, 480, 0.0, 0.8), OptionError);
  EXPECT_THROW(Intrinsics::from_fov(0, 480, 1.0, 0.8), OptionError);
}

}  // namespace
}  // namespace scanclean

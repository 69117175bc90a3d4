// Needs a physical OpenNI2 depth sensor (PrimeSense Carmine / Asus Xtion) and the live driver
// folder: LD_LIBRARY_PATH=<build>/oni-live ctest -L hardware. Excluded from CI (label hardware).

#include <gtest/gtest.h>

#include <chrono>

#include "scanclean/drivers/openni2_source.h"

namespace scanclean {
namespace {

using namespace std::chrono_literals;

TEST(OpenNI2HardwareTest, LiveSensorDelivers30Frames) {
  auto src = make_openni2_source("openni2://");
  src->open();
  const SourceInfo info = src->info();
  EXPECT_TRUE(info.is_live);
  EXPECT_TRUE(info.K.valid());
  RangeFrame f;
  std::uint64_t previous = 0;
  for (int i = 0; i < 30; ++i) {
    ASSERT_EQ(src->next(f, 2000ms), ReadStatus::kOk) << src->last_error();
    if (i > 0) {
      EXPECT_GT(f.index, previous);
    }
    previous = f.index;
    std::size_t valid = 0;
    for (auto d : f.depth.data) valid += d != 0;
    EXPECT_GT(valid, 0u);
  }
}

}  // namespace
}  // namespace scanclean

// The OpenNI2 source with Debian's system driver folder (/usr/lib/x86_64-linux-gnu/OpenNI2/
// Drivers: PS1080, PSLink, OniFile, DummyDevice) and no sensor attached. This binary is built
// WITHOUT the private driver-folder rpath, so libOpenNI2.so.0 is the system one.

#include <gtest/gtest.h>

#include <string>

#include "scanclean/core/errors.h"
#include "scanclean/drivers/openni2_source.h"

namespace scanclean {
namespace {

TEST(OpenNI2SystemTest, NoSensorGivesUnavailableError) {
  const OpenNI2DeviceList list = list_openni2_devices();
  ASSERT_TRUE(list.initialized) << list.error;
  EXPECT_EQ(list.driver_folder.find("/build"), std::string::npos) << list.driver_folder;
  if (!list.devices.empty()) GTEST_SKIP() << "a depth sensor is attached: " << list.devices[0].uri;
  auto src = make_openni2_source("openni2://");
  try {
    src->open();
    FAIL() << "expected UnavailableError";
  } catch (const UnavailableError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("no depth sensor found"), std::string::npos) << what;
    EXPECT_NE(what.find("run scanclean devices"), std::string::npos) << what;
    EXPECT_NE(what.find("no devices found"), std::string::npos) << what;  // OpenNI's own text
  }
}

TEST(OpenNI2SystemTest, SpecificMissingDeviceGivesUnavailableError) {
  auto src = make_openni2_source("openni2://1d27/0601@9/9");
  EXPECT_THROW(src->open(), UnavailableError);
}

}  // namespace
}  // namespace scanclean

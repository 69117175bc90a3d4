// UsbProbe against the real libusb (no USB bus in CI containers: 0 devices is fine), the
// known-sensor table and the permission diagnosis.

#include <gtest/gtest.h>

#include <chrono>

#include "scanclean/drivers/usb_probe.h"

namespace scanclean {
namespace {

TEST(UsbProbeTest, LibusbInitializesAndEnumerates) {
  const UsbEnvironment env = usb_environment();
  EXPECT_EQ(env.libusb_version.rfind("1.", 0), 0u) << env.libusb_version;
  std::vector<UsbDeviceReport> devices;
  ASSERT_NO_THROW(devices = probe_usb_devices());
  for (const auto& d : devices) {
    EXPECT_GT(d.bus + d.address, 0);
    // Only known sensors are opened, and a failed open always carries a diagnosis.
    EXPECT_EQ(d.open_attempted, d.known.has_value());
    if (d.open_error != UsbOpenError::kOk) {
      EXPECT_FALSE(d.diagnosis.empty());
    }
  }
  if (!env.usb_fs_present) {
    EXPECT_TRUE(devices.empty());
  }
}

TEST(UsbProbeTest, KnownSensorTable) {
  const auto carmine = lookup_known_sensor(0x1d27, 0x0601);
  ASSERT_TRUE(carmine.has_value());
  EXPECT_EQ(carmine->family, "primesense");
  EXPECT_TRUE(carmine->debian_openni2);
  EXPECT_TRUE(carmine->debian_udev_rule);
  EXPECT_NE(carmine->name.find("Xtion PRO LIVE"), std::string::npos);
  for (std::uint16_t pid : {0x0600, 0x0609, 0x0500})
    EXPECT_TRUE(lookup_known_sensor(0x1d27, pid).has_value()) << pid;

  const auto kinect1 = lookup_known_sensor(0x045e, 0x02ae);
  ASSERT_TRUE(kinect1.has_value());
  EXPECT_EQ(kinect1->family, "kinect1");
  EXPECT_FALSE(kinect1->debian_openni2);
  EXPECT_TRUE(kinect1->debian_udev_rule);
  EXPECT_FALSE(kinect1->note.empty());
  for (std::uint16_t pid : {0x02bf, 0x02b0, 0x02ad})
    EXPECT_EQ(lookup_known_sensor(0x045e, pid).value().family, "kinect1") << pid;

  const auto kinect2 = lookup_known_sensor(0x045e, 0x02c4);
  ASSERT_TRUE(kinect2.has_value());
  EXPECT_EQ(kinect2->family, "kinect2");
  EXPECT_FALSE(kinect2->debian_udev_rule);
  EXPECT_EQ(lookup_known_sensor(0x045e, 0x02d9).value().family, "kinect2");

  const auto astra = lookup_known_sensor(0x2bc5, 0x0403);
  ASSERT_TRUE(astra.has_value());
  EXPECT_EQ(astra->family, "orbbec");
  EXPECT_EQ(lookup_known_sensor(0x2bc5, 0x0401).value().family, "orbbec");
  EXPECT_FALSE(lookup_known_sensor(0x2bc5, 0x0501).has_value());  // only 04xx

  EXPECT_FALSE(lookup_known_sensor(0x046d, 0xc52b).has_value());  // a Logitech receiver
  EXPECT_FALSE(lookup_known_sensor(0x045e, 0x0745).has_value());  // a Microsoft mouse
  EXPECT_FALSE(lookup_known_sensor(0x1d27, 0x0602).has_value());
  EXPECT_EQ(usb_id_string(0x1d27, 0x0601), "1d27:0601");
}

TEST(UsbProbeTest, AccessErrorPointsAtUdevRulesAndVideoGroup) {
  const std::string covered = diagnose_usb_open_error(UsbOpenError::kAccess, 0x1d27, 0x0601);
  EXPECT_NE(covered.find("1d27:0601"), std::string::npos) << covered;
  EXPECT_NE(covered.find("LIBUSB_ERROR_ACCESS"), std::string::npos) << covered;
  EXPECT_NE(covered.find("/lib/udev/rules.d/60-libopenni2-0.rules"), std::string::npos);
  EXPECT_NE(covered.find("video group"), std::string::npos) << covered;
  EXPECT_EQ(covered.find("ATTR{idVendor}"), std::string::npos) << covered;

  // Orbbec is not in Debian's rules: the text gives a rule line for exactly this id.
  const std::string uncovered = diagnose_usb_open_error(UsbOpenError::kAccess, 0x2bc5, 0x0403);
  EXPECT_NE(uncovered.find("do not cover"), std::string::npos) << uncovered;
  EXPECT_NE(uncovered.find("ATTR{idVendor}==\"2bc5\""), std::string::npos) << uncovered;
  EXPECT_NE(uncovered.find("ATTR{idProduct}==\"0403\""), std::string::npos) << uncovered;
  EXPECT_NE(uncovered.find("GROUP=\"video\""), std::string::npos) << uncovered;

  EXPECT_TRUE(diagnose_usb_open_error(UsbOpenError::kOk, 0x1d27, 0x0601).empty());
  EXPECT_NE(diagnose_usb_open_error(UsbOpenError::kBusy, 0x1d27, 0x0601).find("in use"),
            std::string::npos);
  EXPECT_NE(diagnose_usb_open_error(UsbOpenError::kNoDevice, 0x1d27, 0x0601).find("unplugged"),
            std::string::npos);
}

TEST(UsbProbeTest, WatcherReportsNoEventsWithoutChanges) {
  UsbWatcher watcher;
  const auto t0 = std::chrono::steady_clock::now();
  const auto events = watcher.poll(std::chrono::milliseconds(150));
  const auto waited = std::chrono::steady_clock::now() - t0;
  // Devices present at construction are not events; nothing was plugged in meanwhile.
  EXPECT_TRUE(events.empty());
  EXPECT_GE(waited, std::chrono::milliseconds(140));  // the wait is honoured (hotplug or sleep)
  EXPECT_EQ(watcher.uses_hotplug(), usb_environment().hotplug);
}

}  // namespace
}  // namespace scanclean

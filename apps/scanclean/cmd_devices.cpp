// scanclean devices: pre-flight check for depth sensors. Lists the USB devices libusb sees with
// known depth sensors highlighted and permission problems diagnosed, then OpenNI2's device list
// and driver folder; --watch SECONDS reports devices arriving and leaving.

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <memory>
#include <string>

#include "scanclean/command.h"
#include "scanclean/core/errors.h"
#include "scanclean/summary.h"

#ifdef SCANCLEAN_HAVE_USB
#include "scanclean/drivers/usb_probe.h"
#endif
#ifdef SCANCLEAN_HAVE_OPENNI2
#include "scanclean/drivers/openni2_source.h"
#endif

namespace scanclean::app {
namespace {

struct DevicesOptions {
  double watch_seconds = 0;
  bool all_usb = false;
};

#ifdef SCANCLEAN_HAVE_USB
std::string describe_usb(const UsbDeviceReport& d) {
  std::string line = usb_id_string(d.vendor_id, d.product_id) + "  bus " + std::to_string(d.bus) +
                     " addr " + std::to_string(d.address);
  if (!d.port_path.empty()) line += "  port " + d.port_path;
  if (d.known) line += "  ** " + d.known->name + " **";
  if (!d.product.empty()) line += "  \"" + d.manufacturer + " " + d.product + "\"";
  if (!d.serial.empty()) line += "  serial " + d.serial;
  return line;
}

int usb_section(const DevicesOptions& o, Summary& summary) {
  UsbEnvironment env;
  std::vector<UsbDeviceReport> devices;
  try {
    env = usb_environment();
    devices = probe_usb_devices();
  } catch (const UnavailableError& e) {
    std::printf("USB: %s\n\n", e.what());
    summary.add("USB", "unavailable");
    return 0;
  }
  std::size_t sensors = 0, problems = 0;
  for (const auto& d : devices) {
    sensors += d.known.has_value();
    problems += d.open_error != UsbOpenError::kOk;
  }
  std::printf("USB (libusb %s, hotplug %s): %zu device(s) attached, %zu known depth sensor(s)\n",
              env.libusb_version.c_str(), env.hotplug ? "supported" : "not supported",
              devices.size(), sensors);
  if (devices.empty()) {
    std::printf("  nothing attached%s\n",
                env.usb_fs_present ? ""
                                   : " (/dev/bus/usb does not exist: no USB bus is visible here, "
                                     "e.g. inside a container without --device)");
  }
  for (const auto& d : devices) {
    if (!d.known && !o.all_usb) continue;
    std::printf("  %s\n", describe_usb(d).c_str());
    if (d.known) {
      if (!d.known->note.empty()) std::printf("      note: %s\n", d.known->note.c_str());
      if (d.open_error == UsbOpenError::kOk)
        std::printf("      access: ok\n");
      else
        std::printf("      access: %s\n", d.diagnosis.c_str());
    }
  }
  if (!o.all_usb && devices.size() > sensors)
    std::printf("  (%zu other USB device(s) not shown; --all lists them)\n",
                devices.size() - sensors);
  std::printf("\n");
  summary.add_count("USB devices", devices.size());
  summary.add_count("known depth sensors", sensors);
  summary.add_count("permission/open problems", problems);
  return 0;
}
#endif

#ifdef SCANCLEAN_HAVE_OPENNI2
void openni2_section(Summary& summary) {
  const OpenNI2DeviceList list = list_openni2_devices();
  std::string drivers;
  for (const auto& d : list.drivers) drivers += (drivers.empty() ? "" : ", ") + d;
  std::printf("OpenNI2 driver folder: %s\n  drivers: %s\n", list.driver_folder.c_str(),
              drivers.empty() ? "(none)" : drivers.c_str());
  if (!list.initialized) {
    std::printf("  OpenNI2 could not be initialized: %s\n\n", list.error.c_str());
    summary.add("OpenNI2", "not initialized");
    return;
  }
  std::printf("OpenNI2 devices: %zu\n", list.devices.size());
  for (const auto& d : list.devices) {
    const bool virtual_sensor = d.uri.rfind("vsensor://", 0) == 0;
    std::printf("  %s  %s %s  usb %04x:%04x\n    source URI: %s%s\n", d.uri.c_str(),
                d.vendor.c_str(), d.name.c_str(), d.usb_vendor_id, d.usb_product_id,
                virtual_sensor ? "" : "openni2://", d.uri.c_str());
  }
  if (list.devices.empty()) std::printf("  no depth sensor found\n");
  bool has_ps1080 = false;
  for (const auto& d : list.drivers) has_ps1080 |= d == "libPS1080.so.0";
  if (!has_ps1080)
    std::printf(
        "  hint: this driver folder has no PrimeSense driver (libPS1080.so.0). From the build "
        "tree, run with LD_LIBRARY_PATH=<build>/oni-live to use live sensors.\n");
  std::printf("\n");
  summary.add_count("OpenNI2 devices", list.devices.size());
  summary.add("OpenNI2 driver folder", list.driver_folder);
}
#endif

int run_devices(const DevicesOptions& o) {
  if (o.watch_seconds < 0)
    throw OptionError("--watch must be >= 0 seconds, got " + std::to_string(o.watch_seconds));
  Summary summary("scanclean devices");
#ifdef SCANCLEAN_HAVE_USB
  usb_section(o, summary);
#else
  std::printf("USB: not compiled in (SCANCLEAN_WITH_LIBUSB=OFF)\n\n");
#endif
#ifdef SCANCLEAN_HAVE_OPENNI2
  openni2_section(summary);
#else
  std::printf("OpenNI2: not compiled in (SCANCLEAN_WITH_OPENNI2=OFF)\n\n");
#endif
  if (o.watch_seconds > 0) {
#ifdef SCANCLEAN_HAVE_USB
    UsbWatcher watcher;
    std::printf(
        "Watching USB for %.1f s (%s)...\n", o.watch_seconds,
        watcher.uses_hotplug() ? "hotplug events + polling every 0.5 s" : "polling every 0.5 s");
    std::fflush(stdout);
    const auto t0 = std::chrono::steady_clock::now();
    std::size_t events = 0;
    while (true) {
      const double elapsed =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      if (elapsed >= o.watch_seconds) break;
      const double left_ms = (o.watch_seconds - elapsed) * 1000.0;
      const auto wait = std::chrono::milliseconds(static_cast<long>(std::min(500.0, left_ms)));
      for (const UsbEvent& e : watcher.poll(wait)) {
        ++events;
        const double t =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        std::printf("  [%7.2f s] %s  %s\n", t, e.arrived ? "arrived" : "left   ",
                    describe_usb(e.device).c_str());
        if (e.arrived && !e.device.diagnosis.empty())
          std::printf("      access: %s\n", e.device.diagnosis.c_str());
        std::fflush(stdout);
      }
    }
    std::printf("  %zu event(s)\n\n", events);
    summary.add_count("USB events", events);
#else
    std::printf("--watch needs libusb support (SCANCLEAN_WITH_LIBUSB=ON)\n");
#endif
  }
  summary.print();
  return 0;
}

const CommandRegistrar kRegistrar{
    {"devices", "List attached depth sensors (USB and OpenNI2) and diagnose permission problems",
     80, [](CLI::App& cmd) {
       auto o = std::make_shared<DevicesOptions>();
       cmd.add_option("--watch", o->watch_seconds,
                      "Keep watching for this many seconds and report USB devices arriving and "
                      "leaving (hotplug where supported, else polling every 0.5 s)")
           ->check(non_negative_number());
       cmd.add_flag("--all", o->all_usb, "List every USB device, not only known depth sensors");
       cmd.footer(
           "Known sensors: PrimeSense Carmine / Asus Xtion (1d27:0600/0601/0609/0500, usable "
           "through OpenNI2), Kinect v1 (045e:02ae/02bf/02b0/02ad) and v2 (045e:02c4/02d9), "
           "Orbbec (2bc5:04xx). Permission denied (LIBUSB_ERROR_ACCESS) means the udev rules "
           "(/lib/udev/rules.d/60-libopenni2-0.rules) or the video group membership are "
           "missing. Exit code 0 also when nothing is attached.\n\n" +
           cmd.get_footer());
       return [o] { return run_devices(*o); };
     }}};

}  // namespace
}  // namespace scanclean::app

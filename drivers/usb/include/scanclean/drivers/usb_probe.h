#pragma once
//! \file usb_probe.h
//! USB pre-flight checks for depth sensors with libusb-1.0 (docs/SENSORS.md §6): enumeration, the
//! known-sensor table, permission diagnosis and hotplug events with a polling fallback. Backs
//! `scanclean devices`. No libusb types appear here.

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace scanclean {

//! One entry of the known depth-sensor table.
struct KnownSensor {
  std::uint16_t vendor_id = 0, product_id = 0;
  std::string name;    //!< e.g. "PrimeSense Carmine 1.09 / Asus Xtion PRO LIVE"
  std::string family;  //!< "primesense", "kinect1", "kinect2", "orbbec"
  //! Usable through Debian's OpenNI2 (PS1080 driver). Kinect v1/v2 need libfreenect drivers and
  //! Orbbec needs Orbbec's OpenNI2 fork, none of which Debian ships.
  bool debian_openni2 = false;
  //! Covered by Debian's udev rules /lib/udev/rules.d/60-libopenni2-0.rules.
  bool debian_udev_rule = false;
  std::string note;  //!< what is needed to use it ("" when nothing)
};

//! The table entry for vid:pid, or nullopt for devices that are not known depth sensors.
//! Orbbec matches any 2bc5:04xx. Pure function, thread-safe.
std::optional<KnownSensor> lookup_known_sensor(std::uint16_t vendor_id, std::uint16_t product_id);

//! "vvvv:pppp" in lower-case hex.
std::string usb_id_string(std::uint16_t vendor_id, std::uint16_t product_id);

//! libusb error codes the diagnosis distinguishes (same values as libusb's enum).
enum class UsbOpenError : int {
  kOk = 0,
  kIo = -1,
  kAccess = -3,
  kNoDevice = -4,
  kBusy = -6,
  kNotSupported = -12,
  kOther = -99
};

//! Plain-language diagnosis of a failed libusb_open on vid:pid, with what to do. For kAccess it
//! names the udev rules (/lib/udev/rules.d/60-libopenni2-0.rules, MODE 0666 GROUP video) and the
//! video group, or gives a rule line when Debian's rules do not cover the id. "" for kOk.
//! Pure function, thread-safe.
std::string diagnose_usb_open_error(UsbOpenError error, std::uint16_t vendor_id,
                                    std::uint16_t product_id);

struct UsbDeviceReport {
  std::uint16_t vendor_id = 0, product_id = 0;
  int bus = 0, address = 0;
  std::string port_path;  //!< e.g. "1-2.3" ("" when unknown)
  std::optional<KnownSensor> known;
  //! Only known sensors are opened (to read strings and check permissions).
  bool open_attempted = false;
  UsbOpenError open_error = UsbOpenError::kOk;
  std::string manufacturer, product, serial;  //!< from the string descriptors, when readable
  std::string diagnosis;                      //!< diagnose_usb_open_error(...) when opening failed
};

//! Version and capabilities of the libusb in use.
struct UsbEnvironment {
  std::string libusb_version;   //!< e.g. "1.0.26.11724"
  bool hotplug = false;         //!< LIBUSB_CAP_HAS_HOTPLUG
  bool usb_fs_present = false;  //!< /dev/bus/usb exists (false in most containers)
};

//! Initializes libusb, reads its version and capabilities. \throw UnavailableError when
//! libusb_init fails.
UsbEnvironment usb_environment();

//! Every attached USB device (0 in a container without /dev/bus/usb), known sensors opened once
//! to read their strings and diagnose permissions. \throw UnavailableError when libusb_init or
//! the device list fails.
std::vector<UsbDeviceReport> probe_usb_devices();

//! An attached/removed device reported by UsbWatcher.
struct UsbEvent {
  bool arrived = true;  //!< false = left
  UsbDeviceReport device;
};

//! Watches for devices arriving and leaving. Uses libusb hotplug callbacks where supported and,
//! because uevents often never reach libusb inside containers, also re-enumerates on every
//! poll() and reports differences to the previous snapshot (the polling fallback). Devices
//! present at construction are not reported. Not thread-safe.
class UsbWatcher {
 public:
  //! \throw UnavailableError when libusb_init fails.
  UsbWatcher();
  ~UsbWatcher();
  UsbWatcher(const UsbWatcher&) = delete;
  UsbWatcher& operator=(const UsbWatcher&) = delete;

  //! Waits up to `wait` for hotplug events, then re-enumerates; returns arrivals and departures.
  std::vector<UsbEvent> poll(std::chrono::milliseconds wait);
  //! True when libusb hotplug callbacks are registered (else polling only).
  bool uses_hotplug() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace scanclean

#include "scanclean/drivers/usb_probe.h"

#include <libusb.h>
#include <sys/time.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <filesystem>
#include <set>
#include <thread>
#include <tuple>

#include "scanclean/core/errors.h"

namespace scanclean {
namespace {

// Debian's /lib/udev/rules.d/60-libopenni2-0.rules (MODE 0666, GROUP video) covers these ids.
constexpr std::array<std::uint16_t, 12> kRulesPrimeSense = {
    0x0200, 0x0300, 0x0400, 0x0401, 0x0500, 0x0600, 0x0601, 0x0609, 0x1280, 0x2100, 0x2200, 0xf9db};
constexpr std::array<std::uint16_t, 6> kRulesMicrosoft = {0x02ae, 0x02ad, 0x02b0,
                                                          0x02be, 0x02bf, 0x02c2};

bool in_debian_rules(std::uint16_t vid, std::uint16_t pid) {
  if (vid == 0x1d27)
    return std::find(kRulesPrimeSense.begin(), kRulesPrimeSense.end(), pid) !=
           kRulesPrimeSense.end();
  if (vid == 0x045e)
    return std::find(kRulesMicrosoft.begin(), kRulesMicrosoft.end(), pid) != kRulesMicrosoft.end();
  return false;
}

struct TableEntry {
  std::uint16_t vid, pid;
  const char* name;
  const char* family;
  bool openni2;
  const char* note;
};

constexpr const char* kFreenect1 =
    "Kinect v1 needs an OpenNI2 FreenectDriver (libfreenect), which Debian does not ship";
constexpr const char* kFreenect2 =
    "Kinect v2 needs libfreenect2 and its OpenNI2 driver, which Debian does not ship";

constexpr TableEntry kTable[] = {
    {0x1d27, 0x0600, "PrimeSense Carmine 1.08 / Asus Xtion PRO", "primesense", true, ""},
    {0x1d27, 0x0601, "PrimeSense Carmine 1.09 / Asus Xtion PRO LIVE", "primesense", true, ""},
    {0x1d27, 0x0609, "PrimeSense PS1080 sensor (product 0609)", "primesense", true, ""},
    {0x1d27, 0x0500, "PrimeSense PS1080 sensor (product 0500)", "primesense", true, ""},
    {0x045e, 0x02ae, "Microsoft Kinect v1 (Xbox 360) camera", "kinect1", false, kFreenect1},
    {0x045e, 0x02bf, "Microsoft Kinect for Windows v1 camera", "kinect1", false, kFreenect1},
    {0x045e, 0x02b0, "Microsoft Kinect v1 motor", "kinect1", false, kFreenect1},
    {0x045e, 0x02ad, "Microsoft Kinect v1 audio", "kinect1", false, kFreenect1},
    {0x045e, 0x02c4, "Microsoft Kinect v2 (Kinect for Xbox One)", "kinect2", false, kFreenect2},
    {0x045e, 0x02d9, "Microsoft Kinect v2 (preview/alternate id)", "kinect2", false, kFreenect2},
};

std::string error_name(UsbOpenError e) {
  switch (e) {
    case UsbOpenError::kOk:
      return "LIBUSB_SUCCESS";
    case UsbOpenError::kIo:
      return "LIBUSB_ERROR_IO";
    case UsbOpenError::kAccess:
      return "LIBUSB_ERROR_ACCESS";
    case UsbOpenError::kNoDevice:
      return "LIBUSB_ERROR_NO_DEVICE";
    case UsbOpenError::kBusy:
      return "LIBUSB_ERROR_BUSY";
    case UsbOpenError::kNotSupported:
      return "LIBUSB_ERROR_NOT_SUPPORTED";
    case UsbOpenError::kOther:
      return "libusb error";
  }
  return "libusb error";
}

UsbOpenError to_open_error(int rc) {
  switch (rc) {
    case LIBUSB_SUCCESS:
      return UsbOpenError::kOk;
    case LIBUSB_ERROR_IO:
      return UsbOpenError::kIo;
    case LIBUSB_ERROR_ACCESS:
      return UsbOpenError::kAccess;
    case LIBUSB_ERROR_NO_DEVICE:
      return UsbOpenError::kNoDevice;
    case LIBUSB_ERROR_BUSY:
      return UsbOpenError::kBusy;
    case LIBUSB_ERROR_NOT_SUPPORTED:
      return UsbOpenError::kNotSupported;
    default:
      return UsbOpenError::kOther;
  }
}

// RAII libusb context.
struct Context {
  libusb_context* ctx = nullptr;
  Context() {
    const int rc = libusb_init(&ctx);
    if (rc != LIBUSB_SUCCESS)
      throw UnavailableError(std::string("libusb_init failed: ") + libusb_error_name(rc) +
                             " (no USB support in this environment)");
  }
  ~Context() {
    if (ctx != nullptr) libusb_exit(ctx);
  }
  Context(const Context&) = delete;
  Context& operator=(const Context&) = delete;
};

std::string read_string(libusb_device_handle* h, std::uint8_t index) {
  if (index == 0) return {};
  unsigned char buf[256];
  const int n = libusb_get_string_descriptor_ascii(h, index, buf, sizeof buf);
  return n > 0 ? std::string(reinterpret_cast<const char*>(buf), static_cast<std::size_t>(n))
               : std::string();
}

UsbDeviceReport describe(libusb_device* dev, bool open_known) {
  UsbDeviceReport r;
  libusb_device_descriptor desc{};
  if (libusb_get_device_descriptor(dev, &desc) != LIBUSB_SUCCESS) return r;
  r.vendor_id = desc.idVendor;
  r.product_id = desc.idProduct;
  r.bus = libusb_get_bus_number(dev);
  r.address = libusb_get_device_address(dev);
  std::uint8_t ports[8];
  const int n = libusb_get_port_numbers(dev, ports, sizeof ports);
  if (n > 0) {
    r.port_path = std::to_string(r.bus) + "-";
    for (int i = 0; i < n; ++i) r.port_path += (i ? "." : "") + std::to_string(ports[i]);
  }
  r.known = lookup_known_sensor(r.vendor_id, r.product_id);
  if (r.known && open_known) {
    r.open_attempted = true;
    libusb_device_handle* h = nullptr;
    const int rc = libusb_open(dev, &h);
    r.open_error = to_open_error(rc);
    if (rc == LIBUSB_SUCCESS) {
      r.manufacturer = read_string(h, desc.iManufacturer);
      r.product = read_string(h, desc.iProduct);
      r.serial = read_string(h, desc.iSerialNumber);
      libusb_close(h);
    } else {
      r.diagnosis = diagnose_usb_open_error(r.open_error, r.vendor_id, r.product_id);
    }
  }
  return r;
}

std::vector<UsbDeviceReport> enumerate(libusb_context* ctx, bool open_known) {
  libusb_device** list = nullptr;
  const ssize_t n = libusb_get_device_list(ctx, &list);
  if (n < 0)
    throw UnavailableError(std::string("libusb_get_device_list failed: ") +
                           libusb_error_name(static_cast<int>(n)));
  std::vector<UsbDeviceReport> out;
  for (ssize_t i = 0; i < n; ++i) out.push_back(describe(list[i], open_known));
  libusb_free_device_list(list, 1);
  return out;
}

}  // namespace

std::string usb_id_string(std::uint16_t vendor_id, std::uint16_t product_id) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "%04x:%04x", vendor_id, product_id);
  return buf;
}

std::optional<KnownSensor> lookup_known_sensor(std::uint16_t vendor_id, std::uint16_t product_id) {
  KnownSensor k;
  k.vendor_id = vendor_id;
  k.product_id = product_id;
  k.debian_udev_rule = in_debian_rules(vendor_id, product_id);
  for (const TableEntry& e : kTable) {
    if (e.vid == vendor_id && e.pid == product_id) {
      k.name = e.name;
      k.family = e.family;
      k.debian_openni2 = e.openni2;
      k.note = e.note;
      return k;
    }
  }
  if (vendor_id == 0x2bc5 && (product_id >> 8) == 0x04) {
    k.name = product_id == 0x0403 ? "Orbbec Astra Pro" : "Orbbec Astra family depth sensor";
    k.family = "orbbec";
    k.debian_openni2 = false;
    k.note = "Orbbec sensors need Orbbec's OpenNI2 fork (drivers not in Debian)";
    return k;
  }
  return std::nullopt;
}

std::string diagnose_usb_open_error(UsbOpenError error, std::uint16_t vendor_id,
                                    std::uint16_t product_id) {
  const std::string id = usb_id_string(vendor_id, product_id);
  const std::string head = "cannot open USB device " + id + " (" + error_name(error) + "): ";
  switch (error) {
    case UsbOpenError::kOk:
      return {};
    case UsbOpenError::kAccess: {
      std::string text = head +
                         "permission denied; the udev rule giving your user access is missing or "
                         "not applied. ";
      if (in_debian_rules(vendor_id, product_id)) {
        text +=
            "Debian's rules in /lib/udev/rules.d/60-libopenni2-0.rules (package libopenni2-0) "
            "cover this id with MODE 0666, GROUP video: install that package, add your user to "
            "the video group (sudo usermod -aG video $USER, then log in again), reload the "
            "rules (sudo udevadm control --reload-rules && sudo udevadm trigger) and replug "
            "the sensor.";
      } else {
        char rule[160];
        std::snprintf(rule, sizeof rule,
                      "SUBSYSTEM==\"usb\", ATTR{idVendor}==\"%04x\", ATTR{idProduct}==\"%04x\", "
                      "MODE=\"0666\", GROUP=\"video\"",
                      vendor_id, product_id);
        text +=
            "Debian's /lib/udev/rules.d/60-libopenni2-0.rules do not cover this id: add a "
            "rule such as\n  " +
            std::string(rule) +
            "\nto /etc/udev/rules.d/61-scanclean-sensors.rules, add your user to the video "
            "group (sudo usermod -aG video $USER, then log in again), reload the rules "
            "(sudo udevadm control --reload-rules && sudo udevadm trigger) and replug.";
      }
      return text;
    }
    case UsbOpenError::kBusy:
      return head +
             "the device is in use by another program (close other OpenNI2/libfreenect "
             "programs) or claimed by a kernel driver.";
    case UsbOpenError::kNoDevice:
      return head + "the device was unplugged while being probed; check the cable and hub.";
    case UsbOpenError::kNotSupported:
      return head + "this platform's libusb backend cannot open it (no usbfs access?).";
    case UsbOpenError::kIo:
      return head +
             "I/O error; try another port or cable, or a powered hub (depth sensors "
             "draw more current than many ports supply).";
    case UsbOpenError::kOther:
      return head + "unexpected libusb error.";
  }
  return head;
}

UsbEnvironment usb_environment() {
  Context c;
  UsbEnvironment env;
  const libusb_version* v = libusb_get_version();
  env.libusb_version = std::to_string(v->major) + "." + std::to_string(v->minor) + "." +
                       std::to_string(v->micro) + "." + std::to_string(v->nano);
  env.hotplug = libusb_has_capability(LIBUSB_CAP_HAS_HOTPLUG) != 0;
  std::error_code ec;
  env.usb_fs_present = std::filesystem::exists("/dev/bus/usb", ec);
  return env;
}

std::vector<UsbDeviceReport> probe_usb_devices() {
  Context c;
  return enumerate(c.ctx, /*open_known=*/true);
}

struct UsbWatcher::Impl {
  Context context;
  libusb_hotplug_callback_handle handle = 0;
  bool hotplug = false;
  bool dirty = false;
  std::vector<UsbDeviceReport> snapshot;

  static int LIBUSB_CALL on_hotplug(libusb_context*, libusb_device*, libusb_hotplug_event,
                                    void* user) {
    static_cast<Impl*>(user)->dirty = true;
    return 0;  // stay registered
  }
};

namespace {
using DeviceKey = std::tuple<int, int, std::uint16_t, std::uint16_t>;
DeviceKey key_of(const UsbDeviceReport& r) {
  return {r.bus, r.address, r.vendor_id, r.product_id};
}
}  // namespace

UsbWatcher::UsbWatcher() : impl_(std::make_unique<Impl>()) {
  if (libusb_has_capability(LIBUSB_CAP_HAS_HOTPLUG) != 0) {
    const int rc = libusb_hotplug_register_callback(
        impl_->context.ctx,
        static_cast<libusb_hotplug_event>(LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED |
                                          LIBUSB_HOTPLUG_EVENT_DEVICE_LEFT),
        static_cast<libusb_hotplug_flag>(0), LIBUSB_HOTPLUG_MATCH_ANY, LIBUSB_HOTPLUG_MATCH_ANY,
        LIBUSB_HOTPLUG_MATCH_ANY, &Impl::on_hotplug, impl_.get(), &impl_->handle);
    impl_->hotplug = rc == LIBUSB_SUCCESS;
  }
  impl_->snapshot = enumerate(impl_->context.ctx, /*open_known=*/false);
}

UsbWatcher::~UsbWatcher() {
  if (impl_->hotplug) libusb_hotplug_deregister_callback(impl_->context.ctx, impl_->handle);
}

bool UsbWatcher::uses_hotplug() const {
  return impl_->hotplug;
}

std::vector<UsbEvent> UsbWatcher::poll(std::chrono::milliseconds wait) {
  if (impl_->hotplug) {
    const auto deadline = std::chrono::steady_clock::now() + wait;
    while (!impl_->dirty) {
      const auto left = std::chrono::duration_cast<std::chrono::microseconds>(
          deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0) break;
      timeval tv{static_cast<time_t>(left.count() / 1000000),
                 static_cast<suseconds_t>(left.count() % 1000000)};
      libusb_handle_events_timeout_completed(impl_->context.ctx, &tv, nullptr);
    }
  } else {
    std::this_thread::sleep_for(wait);
  }
  impl_->dirty = false;
  // Polling fallback (and the hotplug path's source of truth): diff against the last snapshot.
  std::vector<UsbDeviceReport> now = enumerate(impl_->context.ctx, /*open_known=*/true);
  std::set<DeviceKey> before, after;
  for (const auto& r : impl_->snapshot) before.insert(key_of(r));
  for (const auto& r : now) after.insert(key_of(r));
  std::vector<UsbEvent> events;
  for (const auto& r : impl_->snapshot)
    if (!after.count(key_of(r))) events.push_back({false, r});
  for (const auto& r : now)
    if (!before.count(key_of(r))) events.push_back({true, r});
  impl_->snapshot = std::move(now);
  return events;
}

}  // namespace scanclean

// OpenNI2 range source, .oni recorder (docs/SENSORS.md §1-3, §7-8). One class for live sensors,
// .oni files and the virtual sensor; everything goes through the real OpenNI2 C++ API.
//
// Debian OpenNI2 rules kept here: never PlaybackControl::seek (SIGSEGV in libOniFile), never
// setSpeed(0) (drops frames), never setVideoMode on files, never the "Dummy" device; files play
// with setSpeed(-1) (manual: one frame per waitForAnyStream) and repeat off; the recorder is
// started ~100 ms before the stream because Recorder::start() is asynchronous.

#include "scanclean/drivers/openni2_source.h"

#include <dlfcn.h>

#include <OpenNI.h>
#include <PS1080.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <thread>

#include <tbb/concurrent_queue.h>

#include "oni_header.h"
#include "scanclean/core/errors.h"

namespace scanclean {
namespace {

//! The virtual sensor's "finished" stream property (drivers/openni2_vsensor/src/
//! vsensor_driver.cpp): 1 once a non-looping stream has delivered its last frame.
constexpr int kVsensorPropertyFinished = 0x53430001;

constexpr const char* kNoSensor = "no depth sensor found; run scanclean devices";

std::string extended_error() {
  const char* e = openni::OpenNI::getExtendedError();
  std::string s = e == nullptr ? "" : e;
  while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
  return s;
}

//! The folder libOpenNI2 loads its drivers from: <folder of libOpenNI2.so.0>/OpenNI2/Drivers.
std::string driver_folder() {
  Dl_info info{};
  if (dladdr(reinterpret_cast<void*>(&oniInitialize), &info) == 0 || info.dli_fname == nullptr)
    return {};
  return (std::filesystem::path(info.dli_fname).parent_path() / "OpenNI2" / "Drivers").string();
}

//! Marks the driver modules OpenNI2 just loaded as never-unloaded (RTLD_NODELETE). OpenNI2
//! dlclose()s its drivers at shutdown; keeping them mapped means a late callback from a driver
//! thread can never jump into unmapped code, repeated initialize/shutdown cycles reuse the
//! loaded modules, and LeakSanitizer can attribute the drivers' own process-lifetime
//! allocations to libOniFile.so & co (tests/lsan.supp) instead of "<unknown module>".
void pin_driver_modules() {
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(driver_folder(), ec)) {
    const std::string name = entry.path().filename().string();
    if (name.size() < 5 || name.compare(name.size() - 5, 5, ".so.0") != 0) continue;
    // RTLD_NOLOAD: only modules OpenNI2 has loaded; the extra reference is kept on purpose.
    dlopen(entry.path().c_str(), RTLD_NOW | RTLD_NOLOAD | RTLD_NODELETE);
  }
}

// Process-wide OpenNI::initialize / shutdown, reference counted.
std::mutex g_context_mutex;
int g_context_refs = 0;

class ContextRef {
 public:
  ContextRef() {
    std::lock_guard<std::mutex> lock(g_context_mutex);
    if (g_context_refs == 0) {
      const openni::Status rc = openni::OpenNI::initialize();
      if (rc != openni::STATUS_OK)
        throw UnavailableError("OpenNI2 could not be initialized (driver folder " +
                               driver_folder() + "): " + extended_error());
      pin_driver_modules();
    }
    ++g_context_refs;
  }
  ~ContextRef() {
    std::lock_guard<std::mutex> lock(g_context_mutex);
    if (--g_context_refs == 0) openni::OpenNI::shutdown();
  }
  ContextRef(const ContextRef&) = delete;
  ContextRef& operator=(const ContextRef&) = delete;
};

std::string hex4(unsigned v) {
  char buf[8];
  std::snprintf(buf, sizeof buf, "%04x", v & 0xffffu);
  return buf;
}

bool starts_with(const std::string& s, const char* prefix) {
  return s.rfind(prefix, 0) == 0;
}

class DisconnectFlag final : public openni::OpenNI::DeviceDisconnectedListener {
 public:
  void watch(const std::string& uri) {
    std::lock_guard<std::mutex> lock(mutex_);
    uri_ = uri;
    fired_ = false;
  }
  void onDeviceDisconnected(const openni::DeviceInfo* info) override {
    std::lock_guard<std::mutex> lock(mutex_);
    if (info != nullptr && uri_ == info->getUri()) fired_ = true;
  }
  bool fired() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return fired_;
  }

 private:
  mutable std::mutex mutex_;
  std::string uri_;
  bool fired_ = false;
};

// One frame read by the listener, converted in the driver's thread.
struct HeldFrame {
  ReadStatus status = ReadStatus::kOk;
  RangeFrame frame;
  std::string error;
};

// Converts a depth frame (copy). Returns kOk or kError with `error` set.
ReadStatus convert_frame(const openni::VideoFrameRef& ref, const Intrinsics& K, float hfov,
                         float vfov, RangeFrame& frame, std::string& error);

// Receives every frame a real-time device emits, in the driver's thread, and keeps it until
// next() takes it: OpenNI2's stream holds only the newest frame, so a reader that is late by a
// frame period (a busy machine) would lose frames otherwise.
class FrameListener final : public openni::VideoStream::NewFrameListener {
 public:
  void set_camera(const Intrinsics& K, float hfov, float vfov) {
    K_ = K;
    hfov_ = hfov;
    vfov_ = vfov;
  }
  void onNewFrame(openni::VideoStream& stream) override {
    // Read only when a frame is waiting. OpenNI2 signals new frames with an auto-reset event,
    // so the signals of frames that arrive while this callback runs collapse into one, and the
    // stream holds only its newest frame: a call can come for a frame the previous call has
    // already read. readFrame() would then wait without a timeout for the next frame, which at
    // the end of a stream never comes, and it waits inside OpenNI2's event dispatch, holding
    // the lock that removeNewFrameListener() takes: close() hung for ever (seen under load in
    // LivePipelineTest). waitForAnyStream with timeout 0 only looks at the stream.
    openni::VideoStream* streams[] = {&stream};
    int ready = -1;
    if (openni::OpenNI::waitForAnyStream(streams, 1, &ready, 0) != openni::STATUS_OK) return;
    openni::VideoFrameRef ref;
    HeldFrame held;
    if (stream.readFrame(&ref) != openni::STATUS_OK || !ref.isValid()) {
      held.status = ReadStatus::kError;
      held.error = "readFrame failed: " + extended_error();
    } else {
      held.status = convert_frame(ref, K_, hfov_, vfov_, held.frame, held.error);
    }
    frames_.push(std::move(held));
  }
  bool try_pop(HeldFrame& out) { return frames_.try_pop(out); }
  void clear() { frames_.clear(); }

 private:
  Intrinsics K_;
  float hfov_ = 0, vfov_ = 0;
  tbb::concurrent_queue<HeldFrame> frames_;
};

class OpenNI2Source final : public RangeSource {
 public:
  OpenNI2Source(std::string uri, OpenNI2Options options) : uri_(std::move(uri)), options_(options) {
    validate(options_);
  }
  ~OpenNI2Source() override { close(); }

  void open() override { open_device(/*start=*/true); }

  // Opens device and stream; starts the stream only when `start` (record_oni starts it later).
  void open_device(bool start);
  void start_stream() {
    if (use_listener_) {
      listener_.clear();
      listener_.set_camera(info_.K, hfov_, vfov_);
      if (stream_.addNewFrameListener(&listener_) == openni::STATUS_OK) frame_listening_ = true;
    }
    if (stream_.start() != openni::STATUS_OK) {
      const std::string e = extended_error();
      close();
      throw UnavailableError("cannot start the depth stream of '" + uri_ + "': " + e);
    }
  }
  ReadStatus next(RangeFrame& frame, std::chrono::milliseconds timeout) override;
  SourceInfo info() const override { return info_; }
  void close() override;
  std::string last_error() const override { return last_error_; }

  openni::VideoStream& stream() { return stream_; }

 private:
  void fill_info();

  std::string uri_;
  OpenNI2Options options_;
  std::string kind_;
  std::unique_ptr<ContextRef> context_;
  openni::Device device_;
  openni::VideoStream stream_;
  DisconnectFlag disconnect_;
  bool listening_ = false;
  bool is_file_ = false;
  bool virtual_device_ = false;
  SourceInfo info_;
  std::optional<std::uint64_t> frame_count_;
  std::uint64_t delivered_ = 0;
  int consecutive_timeouts_ = 0;
  bool end_of_stream_ = false, disconnected_ = false;
  std::string last_error_;
  float hfov_ = 0, vfov_ = 0;
  bool use_listener_ = false;     // real-time devices: frames kept by listener_
  bool frame_listening_ = false;  // listener_ is attached to stream_
  FrameListener listener_;
  ReadStatus timed_out(bool gone);
};

void OpenNI2Source::open_device(bool start) {
  close();
  delivered_ = 0;
  consecutive_timeouts_ = 0;
  end_of_stream_ = disconnected_ = false;
  last_error_.clear();

  std::string device_uri;  // empty = any device
  std::string file;        // for messages
  if (starts_with(uri_, "openni2://")) {
    kind_ = "openni2";
    device_uri = uri_.substr(10);
    // Debian's DummyDevice (URIs Dummy, Oz, PingPong) never joins its stream threads and
    // crashes the process at exit (docs/SENSORS.md §1): refuse it.
    if (device_uri == "Dummy" || device_uri == "Oz" || device_uri == "PingPong")
      throw UnavailableError("OpenNI2's DummyDevice ('" + device_uri +
                             "') is not supported: it crashes at exit; use vsensor://pattern "
                             "or a recording instead");
  } else if (starts_with(uri_, "vsensor://")) {
    kind_ = "vsensor";
    device_uri = uri_;
    const std::string target = uri_.substr(
        10, uri_.find('?') == std::string::npos ? std::string::npos : uri_.find('?') - 10);
    if (target != "default" && target != "pattern") {
      file = target;
      if (!std::filesystem::is_regular_file(std::filesystem::path(target) / "session.json"))
        throw InputError(target, "session.json",
                         "not a recording folder (expected session.json, format "
                         "scanclean-rec/1) for the virtual sensor URI '" +
                             uri_ + "'");
    }
  } else {
    kind_ = "oni";
    device_uri = uri_;
    file = uri_;
    std::error_code ec;
    if (!std::filesystem::is_regular_file(uri_, ec))
      throw InputError(uri_, "open", "no such .oni file (expected an OpenNI recording)");
  }

  context_ = std::make_unique<ContextRef>();
  const openni::Status rc =
      device_.open(device_uri.empty() ? openni::ANY_DEVICE : device_uri.c_str());
  if (rc != openni::STATUS_OK) {
    const std::string e = extended_error();
    context_.reset();
    if (kind_ == "oni") {
      // OpenNI2 says nothing about why; name the one known cause it cannot tell apart.
      if (oni::read_max_node_id(file) == 0u)
        throw InputError(
            file, "header (byte 20)",
            "the stream count is 0, so OpenNI2 cannot play the frames the file holds; the "
            "recorder that wrote it was killed before it stopped, and had written its header "
            "before counting its stream (an openni::Recorder race; scanclean's own recordings "
            "are patched against it). To play a copy: printf '\\001' | dd of=COPY.oni bs=1 "
            "seek=20 conv=notrunc");
      throw InputError(file, "open", "OpenNI2 cannot play this recording (" + e + ")");
    }
    if (kind_ == "vsensor") {
      if (e.find("vsensor:") != std::string::npos && !file.empty())
        throw InputError(file, "recording", e);
      throw UnavailableError("virtual sensor '" + uri_ +
                             "' cannot be opened; is libScancleanVirtualSensor.so.0 in " +
                             driver_folder() + "? (OpenNI2: " + e + ")");
    }
    throw UnavailableError(std::string(kNoSensor) + " (OpenNI2: " + e + ")");
  }
  const auto fail = [&](const std::string& what) {
    const std::string e = extended_error();
    close();
    if (kind_ == "oni") throw InputError(file, "depth stream", what + " (" + e + ")");
    throw UnavailableError(uri_ + ": " + what + " (OpenNI2: " + e + ")");
  };
  if (!device_.hasSensor(openni::SENSOR_DEPTH)) fail("the device has no depth stream");
  is_file_ = device_.isFile();
  if (is_file_) {
    openni::PlaybackControl* playback = device_.getPlaybackControl();
    if (playback == nullptr) fail("no playback control");
    // Manual speed: one frame per waitForAnyStream, nothing dropped. Never 0, never seek.
    if (playback->setSpeed(-1.0f) != openni::STATUS_OK) fail("cannot set manual playback speed");
    if (playback->setRepeatEnabled(false) != openni::STATUS_OK) fail("cannot disable repeat");
  }
  if (stream_.create(device_, openni::SENSOR_DEPTH) != openni::STATUS_OK)
    fail("cannot create the depth stream");
  const std::string dev_uri = device_.getDeviceInfo().getUri();
  const bool virtual_device = starts_with(dev_uri, "vsensor://");
  virtual_device_ = virtual_device;
  if (kind_ == "openni2" && virtual_device) kind_ = "vsensor";
  if (!is_file_ && !virtual_device) {
    // Live device: pick the requested depth unit, keeping the current resolution and rate.
    const openni::PixelFormat want =
        options_.depth_100um ? openni::PIXEL_FORMAT_DEPTH_100_UM : openni::PIXEL_FORMAT_DEPTH_1_MM;
    const openni::VideoMode current = stream_.getVideoMode();
    if (current.getPixelFormat() != want) {
      const openni::SensorInfo& sensor = stream_.getSensorInfo();
      const auto& modes = sensor.getSupportedVideoModes();
      int best = -1;
      for (int i = 0; i < modes.getSize(); ++i) {
        if (modes[i].getPixelFormat() != want) continue;
        const bool same_size = modes[i].getResolutionX() == current.getResolutionX() &&
                               modes[i].getResolutionY() == current.getResolutionY();
        if (best < 0 || (same_size && modes[i].getFps() == current.getFps())) best = i;
      }
      if (best < 0 || stream_.setVideoMode(modes[best]) != openni::STATUS_OK)
        fail(std::string("the device offers no ") +
             (options_.depth_100um ? "DEPTH_100_UM" : "DEPTH_1_MM") + " video mode");
    }
  }
  if (is_file_) {
    // A recording whose writer was killed has no frame count in its header (0): unknown.
    const int n = device_.getPlaybackControl()->getNumberOfFrames(stream_);
    if (n > 0) frame_count_ = static_cast<std::uint64_t>(n);
  } else {
    int n = 0;
    if (stream_.isPropertySupported(ONI_STREAM_PROPERTY_NUMBER_OF_FRAMES) &&
        stream_.getProperty(ONI_STREAM_PROPERTY_NUMBER_OF_FRAMES, &n) == openni::STATUS_OK &&
        n >= 0)
      frame_count_ = static_cast<std::uint64_t>(n);
    disconnect_.watch(dev_uri);
    if (openni::OpenNI::addDeviceDisconnectedListener(&disconnect_) == openni::STATUS_OK)
      listening_ = true;
  }
  fill_info();
  // Devices that emit frames on their own clock (live sensors, the real-time virtual sensor);
  // files and the manual-paced virtual sensor emit a frame per wait and keep nothing to lose.
  use_listener_ =
      !is_file_ && (kind_ == "openni2" || uri_.find("pace=realtime") != std::string::npos);
  if (start) start_stream();
}

void OpenNI2Source::fill_info() {
  SourceInfo info;
  info.uri = uri_;
  info.kind = kind_;
  const openni::DeviceInfo& d = device_.getDeviceInfo();
  info.vendor = d.getVendor();
  info.name = d.getName();
  if (d.getUsbVendorId() != 0 || d.getUsbProductId() != 0)
    info.usb_id = hex4(d.getUsbVendorId()) + ":" + hex4(d.getUsbProductId());
  char serial[ONI_MAX_STR] = {0};
  int size = sizeof serial;
  if (device_.isPropertySupported(ONI_DEVICE_PROPERTY_SERIAL_NUMBER) &&
      device_.getProperty(ONI_DEVICE_PROPERTY_SERIAL_NUMBER, serial, &size) == openni::STATUS_OK)
    info.serial.assign(serial, strnlen(serial, sizeof serial));
  info.is_live = kind_ == "openni2";
  info.frame_count = is_file_ ? frame_count_ : std::nullopt;
  if (kind_ == "vsensor") info.frame_count = frame_count_;

  const openni::VideoMode mode = stream_.getVideoMode();
  info.depth_unit_m = mode.getPixelFormat() == openni::PIXEL_FORMAT_DEPTH_100_UM ? 0.0001 : 0.001;
  hfov_ = stream_.getHorizontalFieldOfView();
  vfov_ = stream_.getVerticalFieldOfView();
  if (hfov_ > 0 && vfov_ > 0 && mode.getResolutionX() > 0 && mode.getResolutionY() > 0)
    info.K = Intrinsics::from_fov(mode.getResolutionX(), mode.getResolutionY(), hfov_, vfov_);

  // PS1080 constants, when the device (or the .oni player, for recordings made from one)
  // answers them as depth-stream properties.
  unsigned long long zpd = 0, coeff = 0;
  double zpps = 0, lddis = 0;
  if (stream_.getProperty(XN_STREAM_PROPERTY_ZERO_PLANE_DISTANCE, &zpd) == openni::STATUS_OK &&
      stream_.getProperty(XN_STREAM_PROPERTY_ZERO_PLANE_PIXEL_SIZE, &zpps) == openni::STATUS_OK &&
      stream_.getProperty(XN_STREAM_PROPERTY_EMITTER_DCMOS_DISTANCE, &lddis) == openni::STATUS_OK &&
      zpd > 0 && zpps > 0) {
    Ps1080Params p;
    p.zpd_mm = static_cast<double>(zpd);
    p.zpps_mm = zpps;
    p.lddis_cm = lddis;
    if (stream_.getProperty(XN_STREAM_PROPERTY_PARAM_COEFF, &coeff) == openni::STATUS_OK)
      p.param_coeff = static_cast<double>(coeff);
    info.ps1080 = p;
  }
  const bool primesense_usb = d.getUsbVendorId() == 0x1d27 ||
                              (d.getUsbVendorId() == 0x045e &&
                               (d.getUsbProductId() == 0x02ae || d.getUsbProductId() == 0x02bf));
  const std::string vendor = info.vendor;
  if (info.ps1080 || primesense_usb || vendor.find("PrimeSense") != std::string::npos)
    info.noise_model = "nguyen2012";
  info_ = info;
}

ReadStatus convert_frame(const openni::VideoFrameRef& ref, const Intrinsics& K, float hfov,
                         float vfov, RangeFrame& frame, std::string& error) {
  const openni::PixelFormat format = ref.getVideoMode().getPixelFormat();
  double unit = 0;
  if (format == openni::PIXEL_FORMAT_DEPTH_1_MM)
    unit = 0.001;
  else if (format == openni::PIXEL_FORMAT_DEPTH_100_UM)
    unit = 0.0001;
  else {
    error = "unsupported depth pixel format " + std::to_string(static_cast<int>(format)) +
            " (expected DEPTH_1_MM or DEPTH_100_UM)";
    return ReadStatus::kError;
  }
  const int w = ref.getWidth(), h = ref.getHeight();
  const int stride = ref.getStrideInBytes();
  if (w <= 0 || h <= 0 || stride < w * 2 || ref.getDataSize() < stride * (h - 1) + w * 2) {
    error = "malformed depth frame " + std::to_string(ref.getFrameIndex()) + " (" +
            std::to_string(w) + "x" + std::to_string(h) + ", stride " + std::to_string(stride) +
            ", " + std::to_string(ref.getDataSize()) + " bytes)";
    return ReadStatus::kError;
  }
  frame = RangeFrame{};
  frame.index = static_cast<std::uint64_t>(ref.getFrameIndex());
  frame.device_ts_us = static_cast<std::int64_t>(ref.getTimestamp());
  frame.host_ts_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                         std::chrono::steady_clock::now().time_since_epoch())
                         .count();
  frame.depth = Image<std::uint16_t>(w, h);
  const auto* bytes = static_cast<const unsigned char*>(ref.getData());
  for (int v = 0; v < h; ++v)
    std::memcpy(frame.depth.data.data() + static_cast<std::size_t>(v) * w,
                bytes + static_cast<std::size_t>(v) * stride, static_cast<std::size_t>(w) * 2);
  frame.depth_unit_m = unit;
  if (K.valid() && K.width == w && K.height == h)
    frame.K = K;
  else if (hfov > 0 && vfov > 0)
    frame.K = Intrinsics::from_fov(w, h, hfov, vfov);
  return ReadStatus::kOk;
}

ReadStatus OpenNI2Source::timed_out(bool gone) {
  ++consecutive_timeouts_;
  if (gone || (listening_ && disconnect_.fired())) {
    disconnected_ = true;
    last_error_ = "device '" + std::string(device_.getDeviceInfo().getUri()) +
                  "' disconnected after " + std::to_string(delivered_) +
                  " frames; close() and open() to reconnect";
    return ReadStatus::kDisconnected;
  }
  if (frame_count_ && delivered_ >= *frame_count_) {
    end_of_stream_ = true;
    return ReadStatus::kEndOfStream;
  }
  int finished = 0;
  if (virtual_device_ &&
      stream_.getProperty(kVsensorPropertyFinished, &finished) == openni::STATUS_OK &&
      finished == 1) {
    // A real-time virtual sensor emitted its last frame (frames a slow reader missed show as
    // index gaps, as with a real sensor).
    end_of_stream_ = true;
    return ReadStatus::kEndOfStream;
  }
  if (is_file_ && consecutive_timeouts_ >= 3) {
    // Three waits in a row without a frame in manual mode: the player has nothing left (a
    // recording without a frame count, e.g. from a killed recorder, or a truncated file).
    end_of_stream_ = true;
    last_error_ = "the .oni player delivered " + std::to_string(delivered_) + " frames " +
                  (frame_count_ ? "of " + std::to_string(*frame_count_)
                                : std::string("(the file header has no frame count)"));
    return ReadStatus::kEndOfStream;
  }
  if (!is_file_ && options_.disconnect_timeouts > 0 &&
      consecutive_timeouts_ >= options_.disconnect_timeouts) {
    disconnected_ = true;
    last_error_ = "no frame from '" + uri_ + "' in " + std::to_string(consecutive_timeouts_) +
                  " consecutive waits; treating the device as disconnected";
    return ReadStatus::kDisconnected;
  }
  return ReadStatus::kTimeout;
}

ReadStatus OpenNI2Source::next(RangeFrame& frame, std::chrono::milliseconds timeout) {
  if (!stream_.isValid()) {
    last_error_ = "source '" + uri_ + "' is not open";
    return ReadStatus::kError;
  }
  if (end_of_stream_) return ReadStatus::kEndOfStream;
  if (disconnected_) return ReadStatus::kDisconnected;
  const bool gone = listening_ && disconnect_.fired();
  // After a disconnect only frames already delivered by the driver are read (no waiting).
  int wait_ms = gone ? 0 : static_cast<int>(std::clamp<long long>(timeout.count(), 0, 1 << 30));
  // All announced frames delivered: a short wait confirms the end (manual pace produces any
  // further frame at once).
  if (frame_count_ && delivered_ >= *frame_count_) wait_ms = std::min(wait_ms, 50);
  if (frame_listening_) {
    // The listener holds every frame the device emitted: take the oldest, waiting for one in
    // steps of 1 ms up to the timeout.
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(wait_ms);
    HeldFrame held;
    while (!listener_.try_pop(held)) {
      if (std::chrono::steady_clock::now() >= deadline) return timed_out(gone);
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    if (held.status != ReadStatus::kOk) {
      last_error_ = held.error;
      return held.status;
    }
    consecutive_timeouts_ = 0;
    frame = std::move(held.frame);
    ++delivered_;
    return ReadStatus::kOk;
  }
  openni::VideoStream* streams[] = {&stream_};
  int ready = -1;
  const openni::Status rc = openni::OpenNI::waitForAnyStream(streams, 1, &ready, wait_ms);
  if (rc == openni::STATUS_TIME_OUT) return timed_out(gone);
  if (rc != openni::STATUS_OK) {
    last_error_ = "waitForAnyStream failed: " + extended_error();
    return ReadStatus::kError;
  }
  openni::VideoFrameRef ref;
  if (stream_.readFrame(&ref) != openni::STATUS_OK || !ref.isValid()) {
    last_error_ = "readFrame failed: " + extended_error();
    return ReadStatus::kError;
  }
  consecutive_timeouts_ = 0;
  const ReadStatus st = convert_frame(ref, info_.K, hfov_, vfov_, frame, last_error_);
  if (st == ReadStatus::kOk) ++delivered_;
  return st;
}

void OpenNI2Source::close() {
  if (frame_listening_) {
    stream_.removeNewFrameListener(&listener_);
    frame_listening_ = false;
  }
  listener_.clear();
  if (listening_) {
    openni::OpenNI::removeDeviceDisconnectedListener(&disconnect_);
    listening_ = false;
  }
  if (stream_.isValid()) {
    stream_.stop();
    if (is_file_) {
      // libOniFile's player thread walks its stream list without a lock, and after the end of
      // the file it does so in a tight loop while a stream is started; destroying the stream
      // then races with it (SIGSEGV in the player thread, seen in ~8% of runs). Once stopped,
      // the thread only looks at the list every 10 ms (PlayerDevice::MainLoop), so give it
      // time to go back to sleep before the stream is freed.
      std::this_thread::sleep_for(std::chrono::milliseconds(25));
    }
    stream_.destroy();
  }
  if (device_.isValid()) device_.close();
  context_.reset();
  frame_count_.reset();
  is_file_ = false;
}

}  // namespace

void validate(const OpenNI2Options& options) {
  if (options.disconnect_timeouts < 0)
    throw OptionError("OpenNI2Options.disconnect_timeouts must be >= 0 (0 = never), got " +
                      std::to_string(options.disconnect_timeouts));
}

std::unique_ptr<RangeSource> make_openni2_source(const std::string& uri,
                                                 const OpenNI2Options& options) {
  return std::make_unique<OpenNI2Source>(uri, options);
}

namespace {

// A device source whose depth stream is recorded by openni::Recorder while it is read.
class OniRecordingSource final : public RangeSource {
 public:
  OniRecordingSource(std::string device_uri, std::filesystem::path out)
      : uri_(std::move(device_uri)), out_(std::move(out)) {}
  ~OniRecordingSource() override { close(); }

  void open() override {
    if (source_) throw UnavailableError("record_oni: the .oni recording source cannot reconnect");
    OpenNI2Options options;
    options.disconnect_timeouts = 0;  // recording ends on the disconnect callback or end of data
    source_ = std::make_unique<OpenNI2Source>(uri_, options);
    source_->open_device(/*start=*/false);
    // Check the output first: when oniCreateRecorder fails, Debian's libOpenNI2 frees the
    // recorder but leaves the handle pointing at it, and Recorder::destroy() then crashes.
    {
      std::FILE* probe = std::fopen(out_.c_str(), "wb");
      if (probe == nullptr) {
        const int err = errno;
        source_.reset();
        throw IoError(out_.string() + ": cannot create the .oni file: " + std::strerror(err));
      }
      std::fclose(probe);
    }
    auto recorder = std::make_unique<openni::Recorder>();
    if (recorder->create(out_.c_str()) != openni::STATUS_OK) {
      const std::string e = extended_error();
      recorder.release();  // deliberately leaked: destroying it would crash (see above)
      source_.reset();
      throw IoError(out_.string() + ": cannot create the .oni file: " + e);
    }
    recorder_ = std::move(recorder);
    if (recorder_->attach(source_->stream(), /*allowLossyCompression=*/false) != openni::STATUS_OK)
      throw UnavailableError("record_oni: cannot attach the depth stream: " + extended_error());
    if (recorder_->start() != openni::STATUS_OK)
      throw IoError(out_.string() + ": cannot start recording: " + extended_error());
    complete_header();
    // Recorder::start() only posts a message to the recorder thread: give it time before frames
    // arrive, or the first frames are dropped (docs/SENSORS.md §3).
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    source_->start_stream();
  }
  ReadStatus next(RangeFrame& frame, std::chrono::milliseconds timeout) override {
    if (!source_) return ReadStatus::kEndOfStream;
    return source_->next(frame, timeout);
  }
  SourceInfo info() const override {
    SourceInfo i = source_ ? source_->info() : SourceInfo{};
    return i;
  }
  void close() override {
    if (recorder_) {
      recorder_->stop();
      recorder_->destroy();
      recorder_.reset();
    }
    if (source_) source_->close();
  }
  std::string last_error() const override { return source_ ? source_->last_error() : ""; }

 private:
  //! openni::Recorder writes the file header (with the number of attached streams) on its own
  //! thread, from a message create() posts, and rewrites it only when it stops. When that thread
  //! runs before attach() has counted the depth stream, the header says 0 streams until the
  //! recorder stops, and a recording whose process is killed is unplayable. Once the recorder has
  //! written past its header (the attach record), raise the count in place.
  void complete_header() {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    std::error_code ec;
    while (std::filesystem::file_size(out_, ec) <= oni::kHeaderSize || ec) {
      if (std::chrono::steady_clock::now() > deadline)
        throw IoError(out_.string() +
                      ": openni::Recorder wrote no stream record within 10 s of starting");
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    if (!oni::ensure_max_node_id(out_, 1))
      throw IoError(out_.string() +
                    ": cannot write the stream count into the .oni header (byte 20)");
  }

  std::string uri_;
  std::filesystem::path out_;
  std::unique_ptr<OpenNI2Source> source_;
  std::unique_ptr<openni::Recorder> recorder_;
};

}  // namespace

std::unique_ptr<RangeSource> make_oni_recording_source(const std::string& device_uri,
                                                       const std::filesystem::path& out_oni) {
  if (!starts_with(device_uri, "openni2://") && !starts_with(device_uri, "vsensor://"))
    throw OptionError("record_oni: device URI must start with openni2:// or vsensor://, got '" +
                      device_uri + "'");
  return std::make_unique<OniRecordingSource>(device_uri, out_oni);
}

OpenNI2DeviceList list_openni2_devices() {
  OpenNI2DeviceList list;
  list.driver_folder = driver_folder();
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(list.driver_folder, ec)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind("lib", 0) == 0 && name.size() > 5 &&
        name.compare(name.size() - 5, 5, ".so.0") == 0)
      list.drivers.push_back(name);
  }
  std::sort(list.drivers.begin(), list.drivers.end());
  std::unique_ptr<ContextRef> context;
  try {
    context = std::make_unique<ContextRef>();
  } catch (const UnavailableError& e) {
    list.error = e.what();
    return list;
  }
  list.initialized = true;
  openni::Array<openni::DeviceInfo> devices;
  openni::OpenNI::enumerateDevices(&devices);
  for (int i = 0; i < devices.getSize(); ++i) {
    OpenNI2DeviceEntry d;
    d.uri = devices[i].getUri();
    d.vendor = devices[i].getVendor();
    d.name = devices[i].getName();
    d.usb_vendor_id = devices[i].getUsbVendorId();
    d.usb_product_id = devices[i].getUsbProductId();
    list.devices.push_back(d);
  }
  return list;
}

}  // namespace scanclean

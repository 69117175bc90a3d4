// OpenNI2 virtual-sensor driver (docs/SENSORS.md §3, §8): a recording folder (format v1)
// or a generated pattern served as a depth camera through the real OpenNI2 driver protocol
// (Debian's Driver/OniDriverAPI.h, 2.2.0.33). Loaded by libOpenNI2 from a driver folder as
// libScancleanVirtualSensor.so.0; opened with Device::open("vsensor://...").
//
// Protocol notes:
// - tryDevice(uri) claims "vsensor://" URIs and announces them (deviceConnected), after which
//   OpenNI calls deviceOpen(uri). "vsensor://default" is announced at initialize() only when
//   VSENSOR_ANNOUNCE=1, so production processes never see a virtual device.
// - pace=manual (default): OpenNI::waitForAnyStream calls tryManualTrigger() whenever no frame is
//   pending; each call emits exactly one frame (lockstep, lossless). pace=realtime: a stream
//   thread emits frames at the recorded timestamp steps; it is joined in stop() and the
//   destructor.
// - The stream answers VIDEO_MODE, HORIZONTAL/VERTICAL_FOV, MAX/MIN_VALUE, STRIDE, MIRRORING and
//   CROPPING (enabled = FALSE; without it the OniFile player drops every frame of a recording),
//   plus the PS1080 ZPD/ZPPS/LDDIS/ParamCoeff properties when the recording has them.
// - Fault injection: drop=... skips frames (index gaps), disconnect_after=N raises
//   deviceStateChanged(ERROR) and deviceDisconnected after N delivered frames.

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <memory>
#include <mutex>
#include <new>
#include <string>
#include <thread>

// Debian ships no XnLib headers; ONI_EXPORT_DRIVER needs these two macros (docs/SENSORS.md §3).
#define XN_NEW(T, ...) new (std::nothrow) T(__VA_ARGS__)
#define XN_DELETE(p) delete (p)
#include <Driver/OniDriverAPI.h>
#include <PS1080.h>

#include "frame_provider.h"

namespace scanclean::vsensor {
namespace {

using oni::driver::DeviceBase;
using oni::driver::DriverBase;
using oni::driver::StreamBase;

class VsensorDriver;

//! Driver-specific stream property (int, get only): 1 once a non-looping stream has delivered
//! its last frame. drivers/openni2/src/openni2_source.cpp reads it (same value there) to report
//! the end of stream without waiting for a frame count that a slow reader may never reach.
constexpr int kPropertyFinished = 0x53430001;

template <class T>
OniStatus put(void* data, int* size, const T& value) {
  if (data == nullptr || size == nullptr || *size < static_cast<int>(sizeof(T)))
    return ONI_STATUS_BAD_PARAMETER;
  std::memcpy(data, &value, sizeof(T));
  *size = static_cast<int>(sizeof(T));
  return ONI_STATUS_OK;
}

OniDeviceInfo make_device_info(const std::string& uri, const std::string& name) {
  OniDeviceInfo info{};
  std::strncpy(info.uri, uri.c_str(), ONI_MAX_STR - 1);
  std::strncpy(info.vendor, "scanclean", ONI_MAX_STR - 1);
  std::strncpy(info.name, name.c_str(), ONI_MAX_STR - 1);
  info.usbVendorId = 0;
  info.usbProductId = 0;
  return info;
}

class VsensorStream final : public StreamBase {
 public:
  VsensorStream(VsensorDriver& driver, const VsensorUri& uri, const FrameProvider& provider,
                const OniDeviceInfo& info)
      : driver_(driver), uri_(uri), provider_(provider), info_(info) {
    mode_.pixelFormat =
        provider.unit_m() < 0.0005 ? ONI_PIXEL_FORMAT_DEPTH_100_UM : ONI_PIXEL_FORMAT_DEPTH_1_MM;
    mode_.resolutionX = provider.width();
    mode_.resolutionY = provider.height();
    mode_.fps = provider.fps();
  }
  ~VsensorStream() override { stop(); }

  OniStatus start() override {
    stop();
    started_ = true;
    if (uri_.realtime) {
      stop_requested_ = false;
      thread_ = std::thread([this] { run_realtime(); });
    }
    return ONI_STATUS_OK;
  }

  void stop() override {
    {
      std::lock_guard<std::mutex> lock(wake_mutex_);
      stop_requested_ = true;
    }
    wake_.notify_all();
    if (thread_.joinable()) thread_.join();
    started_ = false;
  }

  //! Lockstep: one frame per call while started (called from OpenNI::waitForAnyStream).
  void manual_trigger() {
    if (started_ && !uri_.realtime) emit_next();
  }

  int getRequiredFrameSize() override { return provider_.width() * provider_.height() * 2; }

  OniStatus getProperty(int id, void* data, int* size) override {
    switch (id) {
      case ONI_STREAM_PROPERTY_VIDEO_MODE:
        return put(data, size, mode_);
      case ONI_STREAM_PROPERTY_CROPPING: {
        OniCropping c{};
        c.enabled = FALSE;
        c.width = provider_.width();
        c.height = provider_.height();
        return put(data, size, c);
      }
      case ONI_STREAM_PROPERTY_HORIZONTAL_FOV:
        return put(data, size, static_cast<float>(provider_.hfov_rad()));
      case ONI_STREAM_PROPERTY_VERTICAL_FOV:
        return put(data, size, static_cast<float>(provider_.vfov_rad()));
      case ONI_STREAM_PROPERTY_MAX_VALUE:
        return put(data, size, 65534);
      case ONI_STREAM_PROPERTY_MIN_VALUE:
        return put(data, size, 0);
      case ONI_STREAM_PROPERTY_STRIDE:
        return put(data, size, provider_.width() * 2);
      case ONI_STREAM_PROPERTY_MIRRORING:
        return put(data, size, OniBool{FALSE});
      case ONI_STREAM_PROPERTY_NUMBER_OF_FRAMES:
        // Frames this stream will deliver (finite, non-looping sources only).
        if (uri_.loop) return ONI_STATUS_NOT_SUPPORTED;
        return put(data, size, static_cast<int>(deliverable_frames()));
      case kPropertyFinished: {
        std::lock_guard<std::mutex> lock(state_mutex_);
        bool finished = !uri_.loop;
        for (std::size_t i = position_; finished && i < provider_.frame_count(); ++i)
          if (!uri_.dropped(i)) finished = false;
        return put(data, size, finished ? 1 : 0);
      }
      default:
        break;
    }
    if (const auto ps = provider_.ps1080()) {
      switch (id) {
        case XN_STREAM_PROPERTY_ZERO_PLANE_DISTANCE:
          return put(data, size, static_cast<unsigned long long>(std::llround(ps->zpd_mm)));
        case XN_STREAM_PROPERTY_ZERO_PLANE_PIXEL_SIZE:
          return put(data, size, ps->zpps_mm);
        case XN_STREAM_PROPERTY_EMITTER_DCMOS_DISTANCE:
          return put(data, size, ps->lddis_cm);
        case XN_STREAM_PROPERTY_PARAM_COEFF:
          return put(data, size, static_cast<unsigned long long>(std::llround(ps->param_coeff)));
        default:
          break;
      }
    }
    return ONI_STATUS_NOT_SUPPORTED;
  }

  OniStatus setProperty(int id, const void* data, int size) override {
    if (data == nullptr) return ONI_STATUS_BAD_PARAMETER;
    switch (id) {
      case ONI_STREAM_PROPERTY_VIDEO_MODE: {
        if (size < static_cast<int>(sizeof(OniVideoMode))) return ONI_STATUS_BAD_PARAMETER;
        OniVideoMode m;
        std::memcpy(&m, data, sizeof m);
        const bool same = m.pixelFormat == mode_.pixelFormat &&
                          m.resolutionX == mode_.resolutionX &&
                          m.resolutionY == mode_.resolutionY && m.fps == mode_.fps;
        return same ? ONI_STATUS_OK : ONI_STATUS_NOT_SUPPORTED;
      }
      case ONI_STREAM_PROPERTY_MIRRORING: {
        if (size < static_cast<int>(sizeof(OniBool))) return ONI_STATUS_BAD_PARAMETER;
        OniBool b;
        std::memcpy(&b, data, sizeof b);
        return b ? ONI_STATUS_NOT_SUPPORTED : ONI_STATUS_OK;
      }
      case ONI_STREAM_PROPERTY_CROPPING: {
        if (size < static_cast<int>(sizeof(OniCropping))) return ONI_STATUS_BAD_PARAMETER;
        OniCropping c;
        std::memcpy(&c, data, sizeof c);
        return c.enabled ? ONI_STATUS_NOT_SUPPORTED : ONI_STATUS_OK;
      }
      default:
        return ONI_STATUS_NOT_SUPPORTED;
    }
  }

  OniBool isPropertySupported(int id) override {
    switch (id) {
      case ONI_STREAM_PROPERTY_VIDEO_MODE:
      case ONI_STREAM_PROPERTY_CROPPING:
      case ONI_STREAM_PROPERTY_HORIZONTAL_FOV:
      case ONI_STREAM_PROPERTY_VERTICAL_FOV:
      case ONI_STREAM_PROPERTY_MAX_VALUE:
      case ONI_STREAM_PROPERTY_MIN_VALUE:
      case ONI_STREAM_PROPERTY_STRIDE:
      case ONI_STREAM_PROPERTY_MIRRORING:
        return TRUE;
      case ONI_STREAM_PROPERTY_NUMBER_OF_FRAMES:
        return uri_.loop ? FALSE : TRUE;
      case kPropertyFinished:
        return TRUE;
      case XN_STREAM_PROPERTY_ZERO_PLANE_DISTANCE:
      case XN_STREAM_PROPERTY_ZERO_PLANE_PIXEL_SIZE:
      case XN_STREAM_PROPERTY_EMITTER_DCMOS_DISTANCE:
      case XN_STREAM_PROPERTY_PARAM_COEFF:
        return provider_.ps1080() ? TRUE : FALSE;
      default:
        return FALSE;
    }
  }

 private:
  std::size_t deliverable_frames() const {
    std::size_t n = 0;
    for (std::size_t i = 0; i < provider_.frame_count(); ++i)
      if (!uri_.dropped(i)) ++n;
    return n;
  }
  //! Emits the next frame that is not dropped. Returns false at the end of the data, after a
  //! disconnect or when the frame could not be produced.
  bool emit_next();
  void run_realtime();

  VsensorDriver& driver_;
  const VsensorUri& uri_;
  const FrameProvider& provider_;
  OniDeviceInfo info_;
  OniVideoMode mode_{};

  std::mutex state_mutex_;  // position, loop and delivered counters
  std::size_t position_ = 0, loop_ = 0, delivered_ = 0;
  bool disconnected_ = false;

  std::atomic<bool> started_{false};
  std::thread thread_;
  std::mutex wake_mutex_;
  std::condition_variable wake_;
  bool stop_requested_ = false;
};

class VsensorDevice final : public DeviceBase {
 public:
  VsensorDevice(VsensorDriver& driver, VsensorUri uri, std::unique_ptr<FrameProvider> provider)
      : driver_(driver), uri_(std::move(uri)), provider_(std::move(provider)) {
    info_ = make_device_info(uri_.uri, provider_->device_name());
    mode_.pixelFormat =
        provider_->unit_m() < 0.0005 ? ONI_PIXEL_FORMAT_DEPTH_100_UM : ONI_PIXEL_FORMAT_DEPTH_1_MM;
    mode_.resolutionX = provider_->width();
    mode_.resolutionY = provider_->height();
    mode_.fps = provider_->fps();
    sensor_.sensorType = ONI_SENSOR_DEPTH;
    sensor_.numSupportedVideoModes = 1;
    sensor_.pSupportedVideoModes = &mode_;
  }

  OniStatus getSensorInfoList(OniSensorInfo** infos, int* count) override {
    *infos = &sensor_;
    *count = 1;
    return ONI_STATUS_OK;
  }

  StreamBase* createStream(OniSensorType type) override {
    if (type != ONI_SENSOR_DEPTH || stream_ != nullptr) return nullptr;
    stream_ = new (std::nothrow) VsensorStream(driver_, uri_, *provider_, info_);
    return stream_;
  }

  void destroyStream(StreamBase* stream) override {
    if (stream == stream_) stream_ = nullptr;
    delete stream;
  }

  OniStatus getProperty(int id, void* data, int* size) override {
    if (id == ONI_DEVICE_PROPERTY_SERIAL_NUMBER) {
      const std::string serial = provider_->serial().empty() ? "vsensor" : provider_->serial();
      if (data == nullptr || size == nullptr || *size <= static_cast<int>(serial.size()))
        return ONI_STATUS_BAD_PARAMETER;
      std::memcpy(data, serial.c_str(), serial.size() + 1);
      *size = static_cast<int>(serial.size() + 1);
      return ONI_STATUS_OK;
    }
    return ONI_STATUS_NOT_SUPPORTED;
  }
  OniBool isPropertySupported(int id) override {
    return id == ONI_DEVICE_PROPERTY_SERIAL_NUMBER ? TRUE : FALSE;
  }

  OniStatus tryManualTrigger() override {
    if (stream_ != nullptr) stream_->manual_trigger();
    return ONI_STATUS_OK;
  }

 private:
  VsensorDriver& driver_;
  VsensorUri uri_;
  std::unique_ptr<FrameProvider> provider_;
  OniDeviceInfo info_{};
  OniVideoMode mode_{};
  OniSensorInfo sensor_{};
  VsensorStream* stream_ = nullptr;
};

class VsensorDriver final : public DriverBase {
 public:
  explicit VsensorDriver(OniDriverServices* services) : DriverBase(services) {}

  OniStatus initialize(oni::driver::DeviceConnectedCallback connected,
                       oni::driver::DeviceDisconnectedCallback disconnected,
                       oni::driver::DeviceStateChangedCallback state_changed,
                       void* cookie) override {
    const OniStatus rc = DriverBase::initialize(connected, disconnected, state_changed, cookie);
    if (rc != ONI_STATUS_OK) return rc;
    const char* announce = std::getenv("VSENSOR_ANNOUNCE");
    if (announce != nullptr && std::string(announce) == "1") {
      const OniDeviceInfo info = make_device_info("vsensor://default", "Virtual Sensor");
      deviceConnected(&info);
    }
    return ONI_STATUS_OK;
  }

  OniStatus tryDevice(const char* uri) override {
    if (uri == nullptr || std::strncmp(uri, "vsensor://", 10) != 0) return ONI_STATUS_ERROR;
    try {
      const VsensorUri parsed = parse_vsensor_uri(uri);
      const auto provider = make_frame_provider(parsed);  // validates the recording
      const OniDeviceInfo info = make_device_info(parsed.uri, provider->device_name());
      deviceConnected(&info);
      return ONI_STATUS_OK;
    } catch (const std::exception& e) {
      getServices().errorLoggerAppend("vsensor: %s", e.what());
      return ONI_STATUS_ERROR;
    }
  }

  DeviceBase* deviceOpen(const char* uri, const char* /*mode*/) override {
    try {
      VsensorUri parsed = parse_vsensor_uri(uri == nullptr ? "" : uri);
      auto provider = make_frame_provider(parsed);
      return new VsensorDevice(*this, std::move(parsed), std::move(provider));
    } catch (const std::exception& e) {
      getServices().errorLoggerAppend("vsensor: %s", e.what());
      return nullptr;
    }
  }

  void deviceClose(DeviceBase* device) override { delete device; }
  void shutdown() override {}

  //! Fault injection: the device reports an error state and goes away.
  void announce_disconnect(const OniDeviceInfo& info) {
    deviceStateChanged(&info, ONI_DEVICE_STATE_ERROR);
    deviceDisconnected(&info);
  }
};

bool VsensorStream::emit_next() {
  ProvidedFrame data;
  std::uint64_t index = 0;
  std::int64_t ts = 0;
  bool disconnect_now = false;
  {
    std::lock_guard<std::mutex> lock(state_mutex_);
    if (disconnected_) return false;
    const std::size_t n = provider_.frame_count();
    if (n == 0) return false;
    while (true) {
      if (position_ >= n) {
        if (!uri_.loop) return false;
        position_ = 0;
        ++loop_;
      }
      if (!uri_.dropped(position_)) break;
      ++position_;
      if (!uri_.loop && position_ >= n) return false;
      if (uri_.loop && position_ >= n && uri_.drop_every == 0 && uri_.drop_positions.size() >= n)
        return false;  // everything dropped
    }
    try {
      data = provider_.frame(position_);
    } catch (const std::exception&) {
      return false;
    }
    // Loops continue the index and timestamp sequences.
    if (loop_ > 0) {
      const ProvidedFrame first = provider_.stamp(0), last = provider_.stamp(n - 1);
      const std::uint64_t index_span = last.index - first.index + 1;
      const std::int64_t ts_span =
          last.device_ts_us - first.device_ts_us + 1000000 / std::max(1, provider_.fps());
      index = data.index + loop_ * index_span;
      ts = data.device_ts_us + static_cast<std::int64_t>(loop_) * ts_span;
    } else {
      index = data.index;
      ts = data.device_ts_us;
    }
    ++position_;
    ++delivered_;
    if (uri_.disconnect_after > 0 && delivered_ >= uri_.disconnect_after) {
      disconnected_ = true;
      disconnect_now = true;
    }
  }
  OniFrame* frame = getServices().acquireFrame();
  if (frame != nullptr) {
    const int w = provider_.width(), h = provider_.height();
    frame->sensorType = ONI_SENSOR_DEPTH;
    frame->timestamp = static_cast<uint64_t>(std::max<std::int64_t>(ts, 0));
    frame->frameIndex = static_cast<int>(index);
    frame->width = w;
    frame->height = h;
    frame->videoMode = mode_;
    frame->croppingEnabled = FALSE;
    frame->cropOriginX = 0;
    frame->cropOriginY = 0;
    frame->stride = w * 2;
    const std::size_t bytes = static_cast<std::size_t>(w) * h * 2;
    if (data.depth.size() * 2 == bytes && frame->dataSize >= static_cast<int>(bytes)) {
      frame->dataSize = static_cast<int>(bytes);
      std::memcpy(frame->data, data.depth.data(), bytes);
      raiseNewFrame(frame);
    }
    getServices().releaseFrame(frame);
  }
  if (disconnect_now) driver_.announce_disconnect(info_);
  return !disconnect_now;
}

void VsensorStream::run_realtime() {
  using clock = std::chrono::steady_clock;
  // The first frame leaves 20 ms after start(): OpenNI marks the stream started only after the
  // driver's start() returns, and a frame raised before that is discarded.
  const auto t0 = clock::now() + std::chrono::milliseconds(20);
  std::int64_t first_ts = -1;
  std::size_t emitted = 0;
  const std::int64_t period_us = 1000000 / std::max(1, provider_.fps());
  while (true) {
    // Peek at the timestamp of the next frame to pace by the recorded steps.
    std::int64_t next_ts = 0;
    bool looped = false;
    {
      std::lock_guard<std::mutex> lock(state_mutex_);
      // The frame after the last one starts the next loop: it is paced by the frame count, as
      // the loops after it. (Read as "not looped", it got offset 0 when the first timestamp is
      // 0, as the pattern's, and left together with the last frame: a reader saw an index gap
      // at every source's first wrap.)
      looped = loop_ > 0 || position_ >= provider_.frame_count();
      if (position_ < provider_.frame_count()) next_ts = provider_.stamp(position_).device_ts_us;
    }
    if (first_ts < 0) first_ts = next_ts;
    std::int64_t offset = next_ts - first_ts;
    if (offset < 0 || looped) offset = static_cast<std::int64_t>(emitted) * period_us;
    {
      std::unique_lock<std::mutex> lock(wake_mutex_);
      if (wake_.wait_until(lock, t0 + std::chrono::microseconds(offset),
                           [this] { return stop_requested_; }))
        return;
    }
    if (!emit_next()) return;
    ++emitted;
  }
}

}  // namespace
}  // namespace scanclean::vsensor

ONI_EXPORT_DRIVER(scanclean::vsensor::VsensorDriver)

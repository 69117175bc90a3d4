// The OpenNI2 source, recorder and virtual-sensor driver through the real OpenNI2 API, with the
// private driver folder <build>/oni (virtual sensor + OniFile player). No hardware needed.

#include <gtest/gtest.h>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>
#include <limits>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <thread>

#include "openni2_fixtures.h"
#include "scanclean/core/errors.h"
#include "scanclean/drivers/openni2_source.h"
#include "scanclean/pipeline/acquisition.h"
#include "support/data_paths.h"

namespace scanclean {
namespace {

using namespace std::chrono_literals;
using test::vs_mismatches;
using test::write_vs_fixture;

// Records through make_oni_recording_source with the program's acquisition loop, as `scanclean
// record OUT.oni` does (a manual-paced virtual sensor ends after 5 s without a frame).
std::size_t record_oni(const std::string& uri, const std::filesystem::path& oni,
                       std::uint64_t max_frames, double max_seconds) {
  auto src = make_oni_recording_source(uri, oni);
  src->open();
  AcquisitionOptions ao;
  ao.max_frames = max_frames;
  ao.max_seconds = max_seconds;
  ao.timeout = 100ms;
  ao.max_consecutive_timeouts = 50;
  const AcquisitionStats st = acquire(*src, ao, {});
  src->close();
  return st.frames_read;
}

// The .oni header's stream count: the little-endian u32 at byte 20 (packed FileHeaderData of
// OpenNI2's OniDataRecords.h: "NI10", 8 version bytes, u64 max timestamp, u32 max node id).
std::uint32_t oni_header_streams(const std::filesystem::path& oni) {
  std::ifstream in(oni, std::ios::binary);
  unsigned char b[24] = {};
  in.read(reinterpret_cast<char*>(b), sizeof b);
  EXPECT_EQ(in.gcount(), 24) << oni;
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(b), 4), "NI10") << oni;
  return static_cast<std::uint32_t>(b[20]) | static_cast<std::uint32_t>(b[21]) << 8 |
         static_cast<std::uint32_t>(b[22]) << 16 | static_cast<std::uint32_t>(b[23]) << 24;
}

std::unique_ptr<RangeSource> open_source(const std::string& uri, OpenNI2Options o = {}) {
  auto s = make_openni2_source(uri, o);
  s->open();
  return s;
}

TEST(OpenNI2SourceTest, VirtualSensorServesFolderBitExact) {
  const auto fx = write_vs_fixture(test::make_temp_dir("vs") / "rec");
  auto src = open_source("vsensor://" + fx.folder.string() + "?pace=manual");
  const SourceInfo info = src->info();
  EXPECT_EQ(info.kind, "vsensor");
  EXPECT_EQ(info.vendor, "scanclean");
  EXPECT_EQ(info.serial, "SN-FIXTURE-1");
  ASSERT_TRUE(info.frame_count.has_value());
  EXPECT_EQ(*info.frame_count, 5u);
  EXPECT_FALSE(info.is_live);
  EXPECT_EQ(info.noise_model, "none");
  // FOV round trip (float properties): hfov = 2 atan(W / (2 fx)) -> fx again.
  ASSERT_TRUE(info.K.valid());
  EXPECT_EQ(info.K.width, 160);
  EXPECT_EQ(info.K.height, 120);
  EXPECT_NEAR(info.K.fx, 200.0, 1e-3);
  EXPECT_NEAR(info.K.fy, 200.0, 1e-3);
  EXPECT_DOUBLE_EQ(info.K.cx, 80.0);
  EXPECT_DOUBLE_EQ(info.K.cy, 60.0);

  RangeFrame f;
  for (std::size_t i = 0; i < fx.indices.size(); ++i) {
    ASSERT_EQ(src->next(f, 2000ms), ReadStatus::kOk) << "frame " << i << ": " << src->last_error();
    EXPECT_EQ(f.index, fx.indices[i]);
    EXPECT_EQ(f.device_ts_us, fx.timestamps_us[i]);
    EXPECT_GT(f.host_ts_ns, 0);
    EXPECT_DOUBLE_EQ(f.depth_unit_m, 0.001);
    ASSERT_EQ(f.depth.width, 160);
    ASSERT_EQ(f.depth.height, 120);
    EXPECT_EQ(vs_mismatches(f, fx.indices[i]), 0u) << "frame " << i;
    EXPECT_NEAR(f.K.fx, 200.0, 1e-3);
  }
  EXPECT_EQ(src->next(f, 100ms), ReadStatus::kEndOfStream);
  EXPECT_EQ(src->next(f, 100ms), ReadStatus::kEndOfStream);
}

TEST(OpenNI2SourceTest, DepthUnitAndPs1080ConstantsComeFromTheRecording) {
  const auto fx = write_vs_fixture(test::make_temp_dir("vs") / "rec", 2, 160, 120, 0.0001, true);
  auto src = open_source("vsensor://" + fx.folder.string());
  const SourceInfo info = src->info();
  EXPECT_DOUBLE_EQ(info.depth_unit_m, 0.0001);
  ASSERT_TRUE(info.ps1080.has_value());
  EXPECT_DOUBLE_EQ(info.ps1080->zpd_mm, 120.0);
  EXPECT_DOUBLE_EQ(info.ps1080->zpps_mm, 0.1042);
  EXPECT_DOUBLE_EQ(info.ps1080->lddis_cm, 7.5);
  EXPECT_DOUBLE_EQ(info.ps1080->param_coeff, 4.0);
  EXPECT_EQ(info.noise_model, "nguyen2012");
  RangeFrame f;
  ASSERT_EQ(src->next(f, 2000ms), ReadStatus::kOk) << src->last_error();
  EXPECT_DOUBLE_EQ(f.depth_unit_m, 0.0001);
  EXPECT_EQ(vs_mismatches(f, fx.indices[0]), 0u);
}

TEST(OpenNI2SourceTest, DroppedFramesShowAsIndexGaps) {
  const auto fx = write_vs_fixture(test::make_temp_dir("vs") / "rec", 6);
  for (const auto& [query, expected] :
       std::vector<std::pair<std::string, std::vector<std::uint64_t>>>{
           {"drop=1,4", {10, 12, 13, 15}}, {"drop=every3", {10, 11, 13, 14}}}) {
    auto src = open_source("vsensor://" + fx.folder.string() + "?" + query);
    std::vector<std::uint64_t> got;
    RangeFrame f;
    ReadStatus s;
    while ((s = src->next(f, 2000ms)) == ReadStatus::kOk) {
      got.push_back(f.index);
      EXPECT_EQ(vs_mismatches(f, f.index), 0u);
    }
    EXPECT_EQ(s, ReadStatus::kEndOfStream) << query << ": " << src->last_error();
    EXPECT_EQ(got, expected) << query;
  }
}

TEST(OpenNI2SourceTest, DisconnectIsReportedAndReopenWorks) {
  const auto fx = write_vs_fixture(test::make_temp_dir("vs") / "rec", 6);
  auto src = open_source("vsensor://" + fx.folder.string() + "?disconnect_after=3");
  RangeFrame f;
  for (int round = 0; round < 2; ++round) {
    for (int i = 0; i < 3; ++i) {
      ASSERT_EQ(src->next(f, 2000ms), ReadStatus::kOk) << "round " << round << " frame " << i;
      EXPECT_EQ(f.index, fx.indices[i]);
    }
    EXPECT_EQ(src->next(f, 200ms), ReadStatus::kDisconnected);
    EXPECT_NE(src->last_error().find("disconnected"), std::string::npos) << src->last_error();
    EXPECT_EQ(src->next(f, 10ms), ReadStatus::kDisconnected);
    src->close();
    src->open();  // a fresh device: the recording plays again from the start
  }
}

TEST(OpenNI2SourceTest, ConsecutiveTimeoutsCountAsDisconnect) {
  // Realtime pace with loop: an endless live-like stream at 30 fps. Waits of 0 ms are shorter
  // than the frame period, so `disconnect_timeouts` consecutive waits time out.
  const auto fx = write_vs_fixture(test::make_temp_dir("vs") / "rec", 3);
  OpenNI2Options o;
  o.disconnect_timeouts = 3;
  auto src = open_source("vsensor://" + fx.folder.string() + "?pace=realtime&loop=1", o);
  RangeFrame f;
  std::uint64_t previous = 0;
  for (int i = 0; i < 5; ++i) {
    ASSERT_EQ(src->next(f, 2000ms), ReadStatus::kOk) << src->last_error();
    // Looping continues the index sequence (10, 11, 12, 13, ...). A slow reader may miss a
    // real-time frame (a gap, as with a real sensor), so only require increasing indices; the
    // content of index k is recorded frame 10 + (k - 10) mod 3.
    if (i > 0) {
      EXPECT_GT(f.index, previous);
    }
    previous = f.index;
    ASSERT_GE(f.index, 10u);
    EXPECT_EQ(vs_mismatches(f, 10 + (f.index - 10) % 3), 0u) << "index " << f.index;
  }
  ReadStatus s = ReadStatus::kOk;
  for (int i = 0; i < 3 && s != ReadStatus::kDisconnected; ++i) {
    s = src->next(f, 0ms);
    if (s == ReadStatus::kOk) i = -1;  // a frame was already pending; start counting again
  }
  EXPECT_EQ(s, ReadStatus::kDisconnected);
}

TEST(OpenNI2SourceTest, RealtimePaceFollowsTimestamps) {
  const auto fx = write_vs_fixture(test::make_temp_dir("vs") / "rec", 5);
  auto src = open_source("vsensor://" + fx.folder.string() + "?pace=realtime");
  RangeFrame f;
  std::vector<RangeFrame> got;
  ReadStatus s;
  while ((s = src->next(f, 2000ms)) == ReadStatus::kOk) got.push_back(f);
  EXPECT_EQ(s, ReadStatus::kEndOfStream) << src->last_error();
  // Normally all 5; a reader more than one frame period late (loaded machine) misses frames,
  // exactly as with a real sensor, and sees index gaps.
  ASSERT_GE(got.size(), 3u);
  for (std::size_t i = 0; i < got.size(); ++i) {
    if (i > 0) {
      EXPECT_GT(got[i].index, got[i - 1].index);
    }
    EXPECT_EQ(vs_mismatches(got[i], got[i].index), 0u);
    EXPECT_EQ(got[i].device_ts_us, fx.timestamps_us[got[i].index - fx.indices[0]]);
  }
  // Real-time pacing: frames arrive no faster than recorded (host span >= device span minus at
  // most one period of read latency on the first frame).
  const double host_span_us = (got.back().host_ts_ns - got.front().host_ts_ns) / 1000.0;
  const double device_span_us =
      static_cast<double>(got.back().device_ts_us - got.front().device_ts_us);
  EXPECT_GT(device_span_us, 0.0);
  EXPECT_GE(host_span_us, device_span_us - 34000.0);
}

TEST(OpenNI2SourceTest, RealtimeLoopKeepsThePaceAcrossTheWrap) {
  // A pattern of 4 frames at 10 fps, looped: device timestamps from 0, a period apart across
  // the wrap. The first frame of the second loop (index 5) used to leave about 1 ms after the
  // last of the first (paced as "offset 0"), and a reader a little late lost the earlier of the
  // two: an index gap at the first wrap of every live run of the pattern. Now it leaves on
  // schedule, 4 periods after the first frame. Arrival times are taken in the listener, which
  // can only be late: the schedule's start is estimated by the earliest of frames 1-4, and
  // frame 5 must arrive at least 3.5 periods after it (1 ms after frame 4 it was 3 periods).
  auto src = open_source("vsensor://pattern?w=64&h=48&n=4&fps=10&pace=realtime&loop=1");
  RangeFrame f;
  std::vector<RangeFrame> got;
  while (got.size() < 6 && src->next(f, 2000ms) == ReadStatus::kOk) got.push_back(f);
  ASSERT_GE(got.size(), 5u) << src->last_error();
  constexpr double kPeriodMs = 100;
  double start_ms = std::numeric_limits<double>::infinity(), fifth_ms = -1;
  for (std::size_t i = 0; i < got.size(); ++i) {
    const double host_ms = static_cast<double>(got[i].host_ts_ns) / 1e6;
    if (got[i].index <= 4)
      start_ms = std::min(start_ms, host_ms - static_cast<double>(got[i].index - 1) * kPeriodMs);
    if (got[i].index == 5) fifth_ms = host_ms;
    if (i > 0) {
      const double steps = static_cast<double>(got[i].index - got[i - 1].index);
      EXPECT_NEAR(static_cast<double>(got[i].device_ts_us - got[i - 1].device_ts_us),
                  steps * kPeriodMs * 1000, steps)  // whole microseconds
          << "frames " << got[i - 1].index << ", " << got[i].index;
    }
  }
  ASSERT_GE(fifth_ms, 0.0) << "frame 5 was not read";
  EXPECT_GE(fifth_ms - start_ms, 3.5 * kPeriodMs);
}

TEST(OpenNI2SourceTest, RecordOniThenPlayBackBitExact) {
  for (const double unit : {0.001, 0.0001}) {  // DEPTH_1_MM and DEPTH_100_UM streams
    SCOPED_TRACE("unit " + std::to_string(unit));
    const auto dir = test::make_temp_dir("oni");
    const auto fx = write_vs_fixture(dir / "rec", 8, 160, 120, unit, /*ps1080=*/true);
    const auto oni = dir / "x.oni";
    const std::size_t written = record_oni("vsensor://" + fx.folder.string(), oni, 0, 0);
    EXPECT_EQ(written, 8u);
    ASSERT_TRUE(std::filesystem::exists(oni));

    auto src = open_source(oni.string());
    const SourceInfo info = src->info();
    EXPECT_EQ(info.kind, "oni");
    ASSERT_TRUE(info.frame_count.has_value());
    EXPECT_EQ(*info.frame_count, 8u);
    EXPECT_NEAR(info.K.fx, 200.0, 1e-3);  // the FOV was recorded (xnFOV)
    EXPECT_DOUBLE_EQ(info.depth_unit_m, unit);
    // Debian's openni::Recorder does not store the virtual sensor's PS1080 properties (only
    // the recording folder keeps them), so the .oni has no noise-model constants.
    EXPECT_FALSE(info.ps1080.has_value());
    RangeFrame f;
    for (int i = 0; i < 8; ++i) {
      ASSERT_EQ(src->next(f, 2000ms), ReadStatus::kOk)
          << "frame " << i << ": " << src->last_error();
      // The OniFile player renumbers frames 1..N and rebases timestamps to 0, keeping steps.
      EXPECT_EQ(f.index, static_cast<std::uint64_t>(i + 1));
      EXPECT_EQ(f.device_ts_us, fx.timestamps_us[i] - fx.timestamps_us[0]);
      EXPECT_DOUBLE_EQ(f.depth_unit_m, unit);
      EXPECT_EQ(vs_mismatches(f, fx.indices[i]), 0u) << "frame " << i;
    }
    EXPECT_EQ(src->next(f, 200ms), ReadStatus::kEndOfStream);
    EXPECT_EQ(src->next(f, 50ms), ReadStatus::kEndOfStream);
  }
}

TEST(OpenNI2SourceTest, RecordOniStopsAtMaxFrames) {
  const auto dir = test::make_temp_dir("oni");
  const auto fx = write_vs_fixture(dir / "rec", 6);
  const auto oni = dir / "y.oni";
  EXPECT_EQ(record_oni("vsensor://" + fx.folder.string(), oni, 4, 0), 4u);
  auto src = open_source(oni.string());
  EXPECT_EQ(src->info().frame_count.value_or(0), 4u);
  EXPECT_THROW(make_oni_recording_source("file.oni", dir / "z.oni"), OptionError);
  try {
    record_oni("vsensor://" + fx.folder.string(), dir / "no" / "such" / "dir.oni", 2, 0);
    FAIL() << "expected IoError";
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("dir.oni"), std::string::npos) << e.what();
  }
}

TEST(OpenNI2SourceTest, OniWithoutStreamCountNamesTheCause) {
  // What a killed openni::Recorder leaves when its thread wrote the header before attach()
  // counted the stream: OpenNI2 refuses the file with no message; the source says why, and how
  // to repair a copy. The file itself is left as it was.
  const auto dir = test::make_temp_dir("oni0");
  const auto fx = write_vs_fixture(dir / "rec", 3);
  const auto good = dir / "good.oni";
  ASSERT_EQ(record_oni("vsensor://" + fx.folder.string(), good, 0, 0), 3u);
  ASSERT_EQ(oni_header_streams(good), 1u);
  const auto bad = dir / "zero.oni";
  std::filesystem::copy_file(good, bad);
  {
    std::fstream f(bad, std::ios::binary | std::ios::in | std::ios::out);
    f.seekp(20);
    const char zero[4] = {};
    f.write(zero, 4);
  }
  ASSERT_EQ(oni_header_streams(bad), 0u);
  const auto bytes_before = std::filesystem::file_size(bad);
  try {
    open_source(bad.string());
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("zero.oni: header (byte 20): the stream count is 0"), std::string::npos) << m;
    EXPECT_NE(m.find("seek=20"), std::string::npos) << m;
  }
  EXPECT_EQ(oni_header_streams(bad), 0u);
  EXPECT_EQ(std::filesystem::file_size(bad), bytes_before);
  // The repair the message gives: the count back at 1 plays every frame, bit-exact.
  {
    std::fstream f(bad, std::ios::binary | std::ios::in | std::ios::out);
    f.seekp(20);
    f.put('\001');
  }
  auto src = open_source(bad.string());
  RangeFrame frame;
  for (std::size_t i = 0; i < 3; ++i) {
    ASSERT_EQ(src->next(frame, 2000ms), ReadStatus::kOk)
        << "frame " << i << ": " << src->last_error();
    EXPECT_EQ(vs_mismatches(frame, fx.indices[i]), 0u) << "frame " << i;
  }
  EXPECT_EQ(src->next(frame, 200ms), ReadStatus::kEndOfStream);
}

TEST(OpenNI2SourceTest, BadInputsGiveClearErrors) {
  const auto dir = test::make_temp_dir("missing");
  try {
    open_source((dir / "nothere.oni").string());
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("nothere.oni"), std::string::npos) << e.what();
  }
  try {
    open_source("vsensor://" + (dir / "norec").string());
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("norec"), std::string::npos) << e.what();
  }
  EXPECT_THROW(make_openni2_source("x.oni", OpenNI2Options{false, -1}), OptionError);
  EXPECT_THROW(open_source("openni2://Dummy"), UnavailableError);
  // A bad virtual-sensor parameter: the driver's own message comes back through OpenNI2.
  const auto fx = write_vs_fixture(dir / "rec", 1);
  try {
    open_source("vsensor://" + fx.folder.string() + "?pace=fast");
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("pace must be manual or realtime"), std::string::npos)
        << e.what();
  }
  // A folder without frames.csv rows is still a recording: 0 frames, then end of stream.
  const auto empty = write_vs_fixture(dir / "empty", 0);
  auto src = open_source("vsensor://" + empty.folder.string());
  RangeFrame f;
  EXPECT_EQ(src->next(f, 100ms), ReadStatus::kEndOfStream);
}

TEST(OpenNI2SourceTest, NoSensorInPrivateFolderIsUnavailable) {
  // <build>/oni holds only the virtual sensor (not announced) and the .oni player.
  try {
    open_source("openni2://");
    FAIL() << "expected UnavailableError";
  } catch (const UnavailableError& e) {
    EXPECT_NE(std::string(e.what()).find("no depth sensor found"), std::string::npos) << e.what();
  }
}

TEST(OpenNI2SourceTest, AnnouncedVirtualSensorIsTheDefaultDevice) {
  ASSERT_EQ(setenv("VSENSOR_ANNOUNCE", "1", 1), 0);
  const OpenNI2DeviceList list = list_openni2_devices();
  std::unique_ptr<RangeSource> src;
  try {
    src = open_source("openni2://");
  } catch (...) {
    unsetenv("VSENSOR_ANNOUNCE");
    throw;
  }
  unsetenv("VSENSOR_ANNOUNCE");
  ASSERT_TRUE(list.initialized) << list.error;
  ASSERT_EQ(list.devices.size(), 1u);
  EXPECT_EQ(list.devices[0].uri, "vsensor://default");
  EXPECT_NE(std::find(list.drivers.begin(), list.drivers.end(), "libScancleanVirtualSensor.so.0"),
            list.drivers.end());
  EXPECT_EQ(src->info().kind, "vsensor");
  EXPECT_EQ(src->info().K.width, 640);
  RangeFrame f;
  ASSERT_EQ(src->next(f, 2000ms), ReadStatus::kOk) << src->last_error();
  EXPECT_EQ(f.depth.width, 640);
  EXPECT_EQ(f.index, 1u);
  src->close();
  // Without the variable nothing is announced again.
  EXPECT_TRUE(list_openni2_devices().devices.empty());
}

TEST(OpenNI2SourceTest, RealOpenNI1RecordingPlaysCompletely) {
  const auto file = test::recordings_dir() / "oni" / "3dj_test.oni";
  ASSERT_TRUE(std::filesystem::exists(file)) << file;
  auto src = open_source(file.string());
  const SourceInfo info = src->info();
  EXPECT_EQ(info.kind, "oni");
  ASSERT_TRUE(info.frame_count.has_value());
  EXPECT_EQ(*info.frame_count, 12u);
  ASSERT_TRUE(info.K.valid());
  EXPECT_EQ(info.K.width, 640);
  EXPECT_EQ(info.K.height, 480);
  const double hfov = 2 * std::atan(640 / (2 * info.K.fx));
  const double vfov = 2 * std::atan(480 / (2 * info.K.fy));
  EXPECT_NEAR(hfov, 1.014469, 1e-5);
  EXPECT_NEAR(vfov, 0.789809, 1e-5);
  RangeFrame f;
  std::vector<std::int64_t> ts;
  std::size_t valid_sum = 0;
  for (int i = 0; i < 12; ++i) {
    ASSERT_EQ(src->next(f, 2000ms), ReadStatus::kOk) << "frame " << i << ": " << src->last_error();
    EXPECT_EQ(f.index, static_cast<std::uint64_t>(i + 1));
    EXPECT_DOUBLE_EQ(f.depth_unit_m, 0.001);
    std::size_t valid = 0;
    for (auto d : f.depth.data) valid += d != 0;
    EXPECT_GT(valid, 200000u);
    EXPECT_LT(valid, 270000u);
    valid_sum += valid;
    ts.push_back(f.device_ts_us);
  }
  for (std::size_t i = 1; i < ts.size(); ++i) EXPECT_NEAR(ts[i] - ts[i - 1], 33369, 300);
  EXPECT_EQ(src->next(f, 200ms), ReadStatus::kEndOfStream);
  EXPECT_EQ(src->next(f, 50ms), ReadStatus::kEndOfStream);
  std::printf(
      "3dj_test.oni: frames=12 hfov=%.6f vfov=%.6f fx=%.3f mean_valid=%zu "
      "ts_step_first=%lld ts_step_last=%lld noise_model=%s ps1080=%s vendor='%s' "
      "name='%s'\n",
      hfov, vfov, info.K.fx, valid_sum / 12, static_cast<long long>(ts[1] - ts[0]),
      static_cast<long long>(ts[11] - ts[10]), info.noise_model.c_str(), info.ps1080 ? "yes" : "no",
      info.vendor.c_str(), info.name.c_str());
  if (info.ps1080)
    std::printf("3dj_test.oni ps1080: zpd=%g zpps=%g lddis=%g coeff=%g\n", info.ps1080->zpd_mm,
                info.ps1080->zpps_mm, info.ps1080->lddis_cm, info.ps1080->param_coeff);
}

TEST(OpenNI2SourceTest, KilledOniRecordingIsReadableUpToItsLastFrame) {
  // A recorder killed with SIGKILL (child process, real openni::Recorder on an endless
  // real-time virtual sensor) leaves an .oni whose header has no frame count. Debian's OniFile
  // player still plays every frame that reached the file, bit-exact; the source reports an
  // unknown frame count and ends after three empty waits.
  const auto dir = test::make_temp_dir("killed");
  const auto fx = write_vs_fixture(dir / "rec", 6);
  const auto oni = dir / "killed.oni";
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    try {
      record_oni("vsensor://" + fx.folder.string() + "?pace=realtime&loop=1", oni, 0, 30.0);
    } catch (...) {
    }
    _exit(0);
  }
  // Kill it once about ten frames (~92 KB each, high-entropy fixture) reached the file; under
  // sanitizers and load the recorder starts slowly, so wait for the size, not a fixed time.
  const auto deadline = std::chrono::steady_clock::now() + 30s;
  std::error_code ec;
  while (std::chrono::steady_clock::now() < deadline &&
         (!std::filesystem::exists(oni, ec) || std::filesystem::file_size(oni, ec) < 1'000'000))
    std::this_thread::sleep_for(20ms);
  std::this_thread::sleep_for(100ms);
  ASSERT_EQ(kill(child, SIGKILL), 0);
  int status = 0;
  ASSERT_EQ(waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFSIGNALED(status)) << "the recorder ended before it was killed";
  ASSERT_TRUE(std::filesystem::exists(oni));
  // openni::Recorder counts the stream into its header only when it stops, or when attach() ran
  // before its thread wrote the header (a race it loses now and then under load); the recording
  // source completes the header itself, so a killed file always names its one stream.
  EXPECT_EQ(oni_header_streams(oni), 1u);

  auto src = open_source(oni.string());
  EXPECT_FALSE(src->info().frame_count.has_value());
  RangeFrame f;
  std::size_t frames = 0;
  ReadStatus s;
  while ((s = src->next(f, 300ms)) != ReadStatus::kEndOfStream) {
    if (s == ReadStatus::kTimeout) continue;
    ASSERT_EQ(s, ReadStatus::kOk) << src->last_error();
    ++frames;
    EXPECT_EQ(f.index, frames);
    // Frame k of the file is position (k-1) mod 6 of the looped recording.
    EXPECT_EQ(vs_mismatches(f, fx.indices[(frames - 1) % fx.indices.size()]), 0u)
        << "frame " << frames;
  }
  // At least the ~10 frames that were in the file before the kill.
  EXPECT_GE(frames, 8u);
  std::printf("killed .oni: %llu bytes, %zu frames played back (%s)\n",
              static_cast<unsigned long long>(std::filesystem::file_size(oni)), frames,
              src->last_error().c_str());
}

// A real-time device at 1000 fps drained to its end, then closed, 10 times. OpenNI2's new-frame
// signals collapse when frames come faster than its listener thread runs, so the listener can be
// called once more for a frame it has already read; it used to wait inside OpenNI2 for a frame
// that never came, and close() waited for it for ever. That needs a preemption in a short window
// (seen about once in 20 live-pipeline runs on a loaded machine), so this test does not reproduce
// it reliably; it checks that such streams end and close, and a watchdog ends the process after
// 60 s instead of letting a hang go unnoticed.
TEST(OpenNI2SourceTest, FastRealtimeStreamClosesAfterItsEnd) {
  std::atomic<bool> done{false};
  std::thread watchdog([&done] {
    for (int i = 0; i < 600 && !done; ++i) std::this_thread::sleep_for(100ms);
    if (done) return;
    std::fprintf(stderr, "FastRealtimeStreamClosesAfterItsEnd: close() hangs; aborting\n");
    std::_Exit(1);
  });
  std::uint64_t frames = 0;
  for (int cycle = 0; cycle < 10; ++cycle) {
    auto src = open_source("vsensor://pattern?w=32&h=24&n=60&fps=1000&pace=realtime");
    RangeFrame f;
    ReadStatus s;
    while ((s = src->next(f, 100ms)) == ReadStatus::kOk) ++frames;
    EXPECT_EQ(s, ReadStatus::kEndOfStream) << "cycle " << cycle << ": " << src->last_error();
    src->close();
  }
  done = true;
  watchdog.join();
  EXPECT_GT(frames, 0u);
}

TEST(OpenNI2SourceTest, RepeatedOpenCloseCycles) {
  const auto fx = write_vs_fixture(test::make_temp_dir("vs") / "rec", 2);
  for (int cycle = 0; cycle < 3; ++cycle) {
    auto src = open_source("vsensor://" + fx.folder.string());
    RangeFrame f;
    ASSERT_EQ(src->next(f, 2000ms), ReadStatus::kOk) << "cycle " << cycle;
    EXPECT_EQ(vs_mismatches(f, fx.indices[0]), 0u);
  }
}

}  // namespace
}  // namespace scanclean

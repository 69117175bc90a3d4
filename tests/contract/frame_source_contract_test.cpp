// The RangeSource contract, checked on every source kind this build has, all built through the
// one factory (make_range_source): timestamps increase, the end of the stream is reported once
// and again on every later call, frames are well-formed and convert to points.

#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <string>
#include <vector>

#include "drivers/source_factory/source_fixtures.h"
#include "scanclean/drivers/make_range_source.h"
#include "scanclean/pipeline/frame_to_points.h"
#include "support/data_paths.h"

namespace scanclean {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

struct SourceCase {
  std::string name;
  std::size_t expected_frames;  // 0 = at least one
};

std::string PrintCase(const testing::TestParamInfo<SourceCase>& info) {
  return info.param.name;
}

class FrameSourceContractTest : public testing::TestWithParam<SourceCase> {
 protected:
  // The fixture recording (5 frames, 64x48) shared by the recording-based cases.
  static fs::path fixture() {
    static const fs::path dir = [] {
      const fs::path d = test::make_temp_dir("contract") / "rec";
      test::write_fixture_recording(d, 5);
      return d;
    }();
    return dir;
  }

  // The source for a case, or "" with a skip reason.
  std::unique_ptr<RangeSource> make(const std::string& name, std::string& skip) {
    SourceOptions o;
    if (name == "recording_folder") return make_range_source(fixture().string(), o);
    if (name == "depth_images") {
      o.K = test::test_camera(64, 48);
      o.depth_format = "mm";
      return make_range_source((fixture() / "depth").string(), o);
    }
#ifdef SCANCLEAN_HAVE_OPENNI2
    if (name == "vsensor")
      return make_range_source("vsensor://" + fs::absolute(fixture()).string() + "?pace=manual");
    if (name == "oni")
      return make_range_source((test::recordings_dir() / "oni" / "3dj_test.oni").string());
#endif
#ifdef SCANCLEAN_HAVE_SL
    if (name == "structured_light") {
      const fs::path cap = test::shared_data_dir() / "structured_light_kamino410";
      if (!fs::exists(cap / "capture_0")) {
        skip = "shared data not available: " + cap.string();
        return nullptr;
      }
      o.sl_calibration = cap / "calibration_result.xml";
      o.sl_projector_width = 1024;
      o.sl_projector_height = 768;
      return make_range_source((cap / "capture_0").string(), o);
    }
#endif
    skip = "source kind " + name + " is not in this build";
    return nullptr;
  }
};

TEST_P(FrameSourceContractTest, DeliversWellFormedFramesThenEndOfStream) {
  std::string skip;
  auto src = make(GetParam().name, skip);
  if (!src) GTEST_SKIP() << skip;
  src->open();
  const SourceInfo info = src->info();
  EXPECT_FALSE(info.kind.empty());
  EXPECT_GT(info.depth_unit_m, 0);

  RangeFrame f;
  std::size_t frames = 0, timeouts = 0;
  bool have_ts = false;
  std::int64_t last_ts = 0;
  std::uint64_t last_index = 0;
  ReadStatus s = ReadStatus::kOk;
  while (true) {
    s = src->next(f, 5000ms);
    if (s == ReadStatus::kTimeout && ++timeouts < 10) continue;
    if (s != ReadStatus::kOk) break;
    ++frames;
    const int w = f.width(), h = f.height();
    ASSERT_GT(w, 0);
    ASSERT_GT(h, 0);
    if (!f.depth.empty()) {
      EXPECT_EQ(f.depth.width, w);
      EXPECT_EQ(f.depth.height, h);
      EXPECT_EQ(f.depth.data.size(), static_cast<std::size_t>(w) * h);
      EXPECT_GT(f.depth_unit_m, 0);
    }
    if (!f.points) {
      ASSERT_TRUE(f.K.valid()) << "depth frames carry intrinsics";
      EXPECT_EQ(f.K.width, w);
      EXPECT_EQ(f.K.height, h);
    } else {
      EXPECT_EQ(f.points->data.size(), static_cast<std::size_t>(w) * h);
    }
    if (f.confidence) {
      EXPECT_EQ(f.confidence->width, w);
      EXPECT_EQ(f.confidence->height, h);
    }
    if (f.sensor_normals) {
      EXPECT_EQ(f.sensor_normals->width, w);
      EXPECT_EQ(f.sensor_normals->height, h);
    }
    if (have_ts) {
      EXPECT_GT(f.device_ts_us, last_ts) << "frame " << frames;
      EXPECT_GT(f.index, last_index) << "frame " << frames;
    }
    have_ts = true;
    last_ts = f.device_ts_us;
    last_index = f.index;
    if (frames <= 2) {  // converts to points (first frames only: keeps the suite fast)
      FrameToPointsStats st;
      const PointCloud c = frame_to_points(f, info, {}, &st);
      EXPECT_GT(c.size(), 0u);
      EXPECT_EQ(c.grid.rows, h);
      EXPECT_EQ(c.grid.cols, w);
    }
  }
  EXPECT_EQ(s, ReadStatus::kEndOfStream) << src->last_error();
  if (GetParam().expected_frames > 0) {
    EXPECT_EQ(frames, GetParam().expected_frames);
  } else {
    EXPECT_GE(frames, 1u);
  }
  for (int i = 0; i < 3; ++i) EXPECT_EQ(src->next(f, 100ms), ReadStatus::kEndOfStream);
  src->close();
}

INSTANTIATE_TEST_SUITE_P(AllSources, FrameSourceContractTest,
                         testing::Values(SourceCase{"recording_folder", 5},
                                         SourceCase{"depth_images", 5}, SourceCase{"vsensor", 5},
                                         SourceCase{"oni", 12}, SourceCase{"structured_light", 1}),
                         PrintCase);

}  // namespace
}  // namespace scanclean

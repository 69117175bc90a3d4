#include "scanclean/drivers/make_range_source.h"

#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <string>

#include "scanclean/core/errors.h"
#include "source_fixtures.h"
#include "support/data_paths.h"

namespace scanclean {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

std::size_t count_frames(RangeSource& src) {
  src.open();
  RangeFrame f;
  std::size_t n = 0;
  for (int guard = 0; guard < 1000; ++guard) {
    const ReadStatus s = src.next(f, 2000ms);
    if (s == ReadStatus::kOk)
      ++n;
    else if (s == ReadStatus::kEndOfStream)
      break;
    else if (s != ReadStatus::kTimeout)
      ADD_FAILURE() << to_string(s) << " " << src.last_error();
  }
  src.close();
  return n;
}

TEST(MakeRangeSourceTest, UnknownSchemeListsTheKnownOnes) {
  const std::string m = error_of([] { make_range_source("kinect://0"); });
  EXPECT_NE(m.find("unknown scheme \"kinect://\""), std::string::npos) << m;
  EXPECT_NE(m.find("openni2://"), std::string::npos) << m;
  EXPECT_NE(m.find("vsensor://"), std::string::npos) << m;
  EXPECT_THROW(make_range_source("kinect://0"), OptionError);
  EXPECT_THROW(make_range_source(""), OptionError);
}

TEST(MakeRangeSourceTest, MissingPathIsInputError) {
  const fs::path dir = test::make_temp_dir("factory_missing");
  EXPECT_THROW(make_range_source((dir / "nope").string()), InputError);
  const std::string m = error_of([&] { make_range_source((dir / "nope.oni").string()); });
  EXPECT_NE(m.find("nope.oni"), std::string::npos) << m;
  EXPECT_NE(m.find("no such file"), std::string::npos) << m;
}

TEST(MakeRangeSourceTest, UnknownFormatSaysWhatIsAccepted) {
  const fs::path dir = test::make_temp_dir("factory_unknown");
  std::ofstream(dir / "notes.txt") << "hello\n";
  const std::string m = error_of([&] { make_range_source((dir / "notes.txt").string()); });
  EXPECT_NE(m.find("notes.txt"), std::string::npos) << m;
  EXPECT_NE(m.find("recording folder"), std::string::npos) << m;
  EXPECT_NE(m.find("depth images"), std::string::npos) << m;
  EXPECT_THROW(make_range_source((dir / "notes.txt").string()), InputError);
  // A folder with nothing known in it.
  const std::string m2 = error_of([&] { make_range_source(dir.string()); });
  EXPECT_NE(m2.find("no known source format"), std::string::npos) << m2;
}

TEST(MakeRangeSourceTest, RecordingFolderSessionFileAndFileUri) {
  const fs::path dir = test::make_temp_dir("factory_rec") / "rec";
  test::write_fixture_recording(dir, 4);
  for (const std::string& uri :
       {dir.string(), (dir / "session.json").string(), "file://" + dir.string()}) {
    auto src = make_range_source(uri);
    EXPECT_EQ(count_frames(*src), 4u) << uri;
    EXPECT_EQ(src->info().kind, "recording") << uri;
  }
}

TEST(MakeRangeSourceTest, DepthImagesWithIntrinsicsFromOptions) {
  const fs::path dir = test::make_temp_dir("factory_depth") / "rec";
  test::write_fixture_recording(dir, 3);
  SourceOptions o;
  o.K = test::test_camera(64, 48);
  o.depth_format = "mm";
  auto folder = make_range_source((dir / "depth").string(), o);
  EXPECT_EQ(count_frames(*folder), 3u);
  EXPECT_EQ(folder->info().kind, "depth-images");
  auto one = make_range_source((dir / "depth" / "000001.png").string(), o);
  EXPECT_EQ(count_frames(*one), 1u);
  o.depth_format = "bogus";
  EXPECT_THROW(make_range_source((dir / "depth").string(), o), OptionError);
}

TEST(MakeRangeSourceTest, KindsOfThisBuild) {
  const auto kinds = available_source_kinds();
  EXPECT_NE(std::find(kinds.begin(), kinds.end(), "recording"), kinds.end());
#ifdef SCANCLEAN_HAVE_OPENNI2
  EXPECT_NE(std::find(kinds.begin(), kinds.end(), "openni2"), kinds.end());
#endif
}

#ifdef SCANCLEAN_HAVE_OPENNI2
TEST(MakeRangeSourceTest, BundledOniThroughOpenNI2) {
  const fs::path oni = test::recordings_dir() / "oni" / "3dj_test.oni";
  auto src = make_range_source(oni.string());
  EXPECT_EQ(count_frames(*src), 12u);
  EXPECT_EQ(src->info().kind, "oni");
}

TEST(MakeRangeSourceTest, VirtualSensorUri) {
  const fs::path dir = test::make_temp_dir("factory_vs") / "rec";
  test::write_fixture_recording(dir, 4);
  auto src = make_range_source("vsensor://" + fs::absolute(dir).string() + "?pace=manual");
  EXPECT_EQ(count_frames(*src), 4u);
  EXPECT_EQ(src->info().kind, "vsensor");
}
#else
TEST(MakeRangeSourceTest, OpenNI2SourcesNeedTheOption) {
  const std::string m = error_of([] { make_range_source("openni2://"); });
  EXPECT_NE(m.find("built without SCANCLEAN_WITH_OPENNI2"), std::string::npos) << m;
  EXPECT_THROW(make_range_source("openni2://"), UnavailableError);
}
#endif

}  // namespace
}  // namespace scanclean

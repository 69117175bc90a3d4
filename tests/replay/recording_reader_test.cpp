#include "scanclean/replay/recording_reader.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <thread>

#include "replay_fixtures.h"
#include "scanclean/core/errors.h"
#include "scanclean/replay/recording_writer.h"
#include "support/data_paths.h"

namespace scanclean {
namespace {

namespace fs = std::filesystem;

void write_fixture(const fs::path& dir, const std::vector<std::uint64_t>& indices, bool confidence,
                   bool finish = true) {
  const SessionMetadata s = test::fixture_session();
  // No fsync of the index: these tests are about content, not power loss, and stay fast.
  RecordingWriter w(dir, s, RecordingWriterOptions{false});
  for (std::uint64_t i : indices) w.write(test::fixture_frame(s, i, confidence));
  EXPECT_EQ(w.frames_written(), indices.size());
  if (finish) w.finish();
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

void spit(const fs::path& p, const std::string& text) {
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out << text;
}

void expect_frame_equals(const RangeFrame& got, const RangeFrame& want) {
  EXPECT_EQ(got.index, want.index);
  EXPECT_EQ(got.device_ts_us, want.device_ts_us);
  EXPECT_EQ(got.host_ts_ns, want.host_ts_ns);
  EXPECT_EQ(got.depth_unit_m, want.depth_unit_m);
  ASSERT_EQ(got.depth.width, want.depth.width);
  ASSERT_EQ(got.depth.height, want.depth.height);
  EXPECT_EQ(got.depth.data, want.depth.data);  // bit-exact
  EXPECT_EQ(got.K.fx, want.K.fx);
  EXPECT_EQ(got.K.cy, want.K.cy);
  EXPECT_EQ(got.K.dist, want.K.dist);
  ASSERT_EQ(got.confidence.has_value(), want.confidence.has_value());
  if (want.confidence) {
    EXPECT_EQ(got.confidence->data, want.confidence->data);  // bit-exact
  }
}

TEST(RecordingReaderTest, WriterReaderRoundTripIsBitExact) {
  const auto dir = test::make_temp_dir("rec_roundtrip");
  const std::vector<std::uint64_t> indices{3, 4, 5, 9, 10};  // a gap of 3 dropped frames
  write_fixture(dir, indices, true);
  RecordingReader r(dir);
  EXPECT_TRUE(r.warnings().empty());
  const SessionMetadata want = test::fixture_session();
  EXPECT_TRUE(r.session().finalized);
  ASSERT_TRUE(r.session().frame_count);
  EXPECT_EQ(*r.session().frame_count, indices.size());
  EXPECT_EQ(r.session().device.serial, want.device.serial);
  EXPECT_EQ(r.session().K.dist, want.K.dist);
  EXPECT_EQ(r.session().unit_m, want.unit_m);
  EXPECT_EQ(r.session().created, want.created);
  ASSERT_EQ(r.frame_count(), indices.size());
  for (std::size_t i = 0; i < indices.size(); ++i)
    expect_frame_equals(r.read_frame(i), test::fixture_frame(want, indices[i], true));
  EXPECT_TRUE(r.color_file(0).empty());
  EXPECT_THROW(r.read_frame(indices.size()), std::out_of_range);

  // The files are what the format says: 16-bit grayscale PNGs readable by OpenCV directly.
  cv::Mat png = cv::imread((dir / "depth/000000.png").string(), cv::IMREAD_ANYDEPTH);
  ASSERT_EQ(png.type(), CV_16UC1);
  EXPECT_EQ(png.at<std::uint16_t>(5, 7), test::fixture_depth(3, 7, 5));
  const std::string csv = slurp(dir / "frames.csv");
  EXPECT_EQ(csv.substr(0, csv.find('\n')), kFramesCsvHeader);
  EXPECT_NE(csv.find("\n9,1299997,5300006000,depth/000003.png,,confidence/000003.png,0\n"),
            std::string::npos)
      << csv;
  fs::remove_all(dir);
}

TEST(RecordingReaderTest, ReadFrameIsThreadSafe) {
  const auto dir = test::make_temp_dir("rec_threads");
  const std::vector<std::uint64_t> indices{0, 1, 2, 3, 4, 5, 6, 7};
  write_fixture(dir, indices, true);
  const RecordingReader r(dir);
  const SessionMetadata s = test::fixture_session();
  std::vector<int> mismatches(4, 0);
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([&, t] {
      for (int round = 0; round < 5; ++round)
        for (std::size_t i = 0; i < r.frame_count(); ++i) {
          const RangeFrame f = r.read_frame((i + static_cast<std::size_t>(t)) % r.frame_count());
          if (f.depth.data != test::fixture_frame(s, f.index, true).depth.data) ++mismatches[t];
        }
    });
  for (auto& th : threads) th.join();
  EXPECT_EQ(mismatches, std::vector<int>(4, 0));
  fs::remove_all(dir);
}

TEST(RecordingReaderTest, ColourRoundTripIsExact) {
  const auto dir = test::make_temp_dir("rec_colour");
  const SessionMetadata s = test::fixture_session();
  RgbImage rgb(20, 10);  // another size than depth (colour cameras often differ)
  for (int v = 0; v < rgb.height; ++v)
    for (int u = 0; u < rgb.width; ++u)
      rgb(u, v) = {static_cast<std::uint8_t>(u * 12), static_cast<std::uint8_t>(v * 25),
                   static_cast<std::uint8_t>(255 - u - v)};
  {
    RecordingWriter w(dir, s, RecordingWriterOptions{false});
    w.write(test::fixture_frame(s, 0, false), rgb);
    w.write(test::fixture_frame(s, 1, false));  // a frame without colour
    EXPECT_THROW(w.write(test::fixture_frame(s, 2, false), RgbImage{}), InputError);
    w.finish();
  }
  RecordingReader r(dir);
  ASSERT_EQ(r.frame_count(), 2u);
  EXPECT_EQ(r.record(0).color, "color/000000.png");
  EXPECT_EQ(r.color_file(0), dir / "color/000000.png");
  const RgbImage back = r.read_color(0);
  ASSERT_EQ(back.width, 20);
  ASSERT_EQ(back.height, 10);
  EXPECT_EQ(back.data, rgb.data);  // R stays R (OpenCV's BGR handled inside)
  // OpenCV agrees on the channel order: pixel (3, 2) has R = 36, G = 50, B = 250.
  const cv::Mat bgr = cv::imread((dir / "color/000000.png").string(), cv::IMREAD_COLOR);
  EXPECT_EQ(bgr.at<cv::Vec3b>(2, 3), cv::Vec3b(250, 50, 36));
  EXPECT_TRUE(r.color_file(1).empty());
  EXPECT_THROW(r.read_color(1), InputError);
  fs::remove_all(dir);
}

TEST(RecordingReaderTest, RegisteredColourBecomesTheFramesColour) {
  // With registration depth_to_color a colour image of the depth's size is the frame's colour;
  // without registration (or of another size) the frame has none: the pixels do not correspond.
  for (const bool registered : {true, false}) {
    const auto dir = test::make_temp_dir("rec_colour_frame");
    SessionMetadata s = test::fixture_session();
    s.registration = registered ? "depth_to_color" : "off";
    RgbImage rgb(s.width, s.height);
    for (int v = 0; v < rgb.height; ++v)
      for (int u = 0; u < rgb.width; ++u)
        rgb(u, v) = {static_cast<std::uint8_t>(u), static_cast<std::uint8_t>(v), 7};
    {
      RecordingWriter w(dir, s, RecordingWriterOptions{false});
      w.write(test::fixture_frame(s, 0, false), rgb);
      w.write(test::fixture_frame(s, 1, false), RgbImage(3, 2));  // another size
      w.finish();
    }
    RecordingReader r(dir);
    const RangeFrame f0 = r.read_frame(0), f1 = r.read_frame(1);
    EXPECT_EQ(f0.color.has_value(), registered);
    if (registered) {
      EXPECT_EQ(f0.color->data, rgb.data);
    }
    EXPECT_FALSE(f1.color.has_value());
    fs::remove_all(dir);
  }
}

TEST(RecordingReaderTest, WriterValidatesFrames) {
  const auto dir = test::make_temp_dir("rec_writer_checks");
  const SessionMetadata s = test::fixture_session();
  RecordingWriter w(dir, s);
  w.write(test::fixture_frame(s, 5, false));
  EXPECT_THROW(w.write(test::fixture_frame(s, 5, false)), InputError);  // index not increasing
  RangeFrame wrong_size = test::fixture_frame(s, 6, false);
  wrong_size.depth = Image<std::uint16_t>(8, 8, 100);
  EXPECT_THROW(w.write(wrong_size), InputError);
  RangeFrame wrong_unit = test::fixture_frame(s, 6, false);
  wrong_unit.depth_unit_m = 0.001;
  EXPECT_THROW(w.write(wrong_unit), InputError);
  RangeFrame empty = test::fixture_frame(s, 6, false);
  empty.depth = {};
  EXPECT_THROW(w.write(empty), InputError);
  EXPECT_EQ(w.frames_written(), 1u);
  w.finish();
  // A second writer on the same folder refuses to overwrite it.
  EXPECT_THROW(RecordingWriter(dir, s), IoError);
  EXPECT_EQ(RecordingReader(dir).frame_count(), 1u);
  fs::remove_all(dir);
}

TEST(RecordingReaderTest, WritingAfterFinishReopensAndRefinalizes) {
  const auto dir = test::make_temp_dir("rec_reopen");
  const SessionMetadata s = test::fixture_session();
  RecordingWriter w(dir, s);
  w.write(test::fixture_frame(s, 0, false));
  w.finish();
  EXPECT_TRUE(read_session(dir).finalized);
  w.write(test::fixture_frame(s, 1, false));
  EXPECT_FALSE(read_session(dir).finalized);
  EXPECT_EQ(RecordingReader(dir).frame_count(), 2u);
  w.finish();
  EXPECT_EQ(read_session(dir).frame_count, 2u);
  fs::remove_all(dir);
}

TEST(RecordingReaderTest, UnfinishedRecordingIsReadable) {
  const auto dir = test::make_temp_dir("rec_unfinished");
  write_fixture(dir, {0, 1, 2}, false, /*finish=*/false);
  RecordingReader r(dir);
  EXPECT_FALSE(r.session().finalized);
  EXPECT_EQ(r.frame_count(), 3u);
  fs::remove_all(dir);
}

TEST(RecordingReaderTest, KilledWriterLeavesReadablePrefix) {
  const auto dir = test::make_temp_dir("rec_killed");
  const SessionMetadata s = test::fixture_session(64, 48);
  pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    // Child: write frames until killed. _exit: never return into the test framework.
    try {
      RecordingWriter w(dir, s);
      for (std::uint64_t i = 0; i < 100000; ++i) w.write(test::fixture_frame(s, i * 2, true));
    } catch (...) {
      ::_exit(3);
    }
    ::_exit(2);
  }
  // Parent: wait until at least 6 frame lines are on disk, then SIGKILL mid-stream.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  std::size_t lines = 0;
  while (std::chrono::steady_clock::now() < deadline) {
    const std::string csv = slurp(dir / "frames.csv");
    lines = static_cast<std::size_t>(std::count(csv.begin(), csv.end(), '\n'));
    if (lines >= 7) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  ::kill(child, SIGKILL);
  int status = 0;
  ::waitpid(child, &status, 0);
  ASSERT_TRUE(WIFSIGNALED(status)) << "writer exited by itself with status " << status;
  ASSERT_GE(lines, 7u) << "writer too slow to produce 6 frames in 20 s";

  RecordingReader r(dir);
  EXPECT_FALSE(r.session().finalized);
  ASSERT_GE(r.frame_count(), 6u);
  for (std::size_t i = 0; i < r.frame_count(); ++i)
    expect_frame_equals(r.read_frame(i), test::fixture_frame(s, i * 2, true));

  // Same recording, made to look killed in the middle of a line, with that line's files gone:
  // the reader stops at the last complete frame and says so.
  std::string csv = slurp(dir / "frames.csv");
  const std::size_t complete = r.frame_count();
  const std::size_t last_nl = csv.rfind('\n', csv.size() - 2);
  const std::string last_line = csv.substr(last_nl + 1);
  csv = csv.substr(0, last_nl + 1) + last_line.substr(0, last_line.size() / 2);
  spit(dir / "frames.csv", csv);
  fs::remove(dir / ("depth/" + std::string(6 - std::to_string(complete - 1).size(), '0') +
                    std::to_string(complete - 1) + ".png"));
  RecordingReader r2(dir);
  EXPECT_EQ(r2.frame_count(), complete - 1);
  ASSERT_FALSE(r2.warnings().empty());
  EXPECT_NE(r2.warnings().front().find("incomplete last line"), std::string::npos);
  expect_frame_equals(r2.read_frame(complete - 2),
                      test::fixture_frame(s, (complete - 2) * 2, true));
  fs::remove_all(dir);
}

TEST(RecordingReaderTest, LastRowWithMissingFileIsDroppedOnlyWhenNotFinalized) {
  const auto dir = test::make_temp_dir("rec_lastrow");
  write_fixture(dir, {0, 1, 2}, false, /*finish=*/false);
  fs::remove(dir / "depth/000002.png");
  RecordingReader r(dir);
  EXPECT_EQ(r.frame_count(), 2u);
  EXPECT_EQ(r.warnings().size(), 1u);
  fs::remove(dir / "depth/000001.png");  // now a row that is not the last one: an error
  spit(dir / "frames.csv", slurp(dir / "frames.csv"));
  try {
    // Rows 0 and 1 reference existing/missing files; row 2 is dropped, row 1 is then missing.
    RecordingReader bad(dir);
    // Row 1 is not the last row (row 2 still is), so this must throw.
    FAIL() << "accepted a missing file in the middle";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("000001.png"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("line 3"), std::string::npos) << e.what();
  }
  fs::remove_all(dir);
}

//! Builds a valid finalized 3-frame recording, applies `corrupt`, and expects InputError naming
//! `file_part` (and `needle`) either when opening or when reading every frame.
void expect_corrupt_rejected(const std::function<void(const fs::path&)>& corrupt,
                             const std::string& file_part, const std::string& needle) {
  const auto dir = test::make_temp_dir("rec_corrupt");
  write_fixture(dir, {0, 1, 2}, true);
  corrupt(dir);
  try {
    RecordingReader r(dir);
    for (std::size_t i = 0; i < r.frame_count(); ++i) r.read_frame(i);
    ADD_FAILURE() << "accepted corruption expected to mention " << needle;
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(file_part), std::string::npos) << msg;
    EXPECT_NE(msg.find(needle), std::string::npos) << msg;
  }
  fs::remove_all(dir);
}

void replace_in(const fs::path& file, const std::string& from, const std::string& to) {
  std::string text = slurp(file);
  const auto pos = text.find(from);
  ASSERT_NE(pos, std::string::npos) << from;
  text.replace(pos, from.size(), to);
  spit(file, text);
}

TEST(RecordingReaderTest, MalformedRecordingsGiveInputErrorsNamingFileAndRow) {
  expect_corrupt_rejected([](const fs::path& d) { fs::remove(d / "session.json"); }, "session.json",
                          "missing");
  expect_corrupt_rejected(
      [](const fs::path& d) {
        replace_in(d / "session.json", "scanclean-rec/1", "scanclean-rec/7");
      },
      "session.json", "unsupported recording format");
  expect_corrupt_rejected(
      [](const fs::path& d) { replace_in(d / "session.json", "\"width\": 16", "\"width\": 1.5"); },
      "session.json", "depth.width");
  expect_corrupt_rejected(
      [](const fs::path& d) { replace_in(d / "frames.csv", "index,device", "idx,device"); },
      "frames.csv", "line 1: expected the header");
  expect_corrupt_rejected([](const fs::path& d) { replace_in(d / "frames.csv", "\n1,", "\n1;"); },
                          "frames.csv", "line 3: expected 7 comma-separated fields");
  expect_corrupt_rejected([](const fs::path& d) { replace_in(d / "frames.csv", "\n1,", "\nx1,"); },
                          "frames.csv", "line 3: field index");
  expect_corrupt_rejected(
      [](const fs::path& d) { replace_in(d / "frames.csv", ",1033333,", ",10e5,"); }, "frames.csv",
      "line 3: field device_ts_us");
  expect_corrupt_rejected(
      [](const fs::path& d) { replace_in(d / "frames.csv", "\n2,", "\n1,"); }, "frames.csv",
      "line 4: field index: expected a value greater than the previous row's 1");
  expect_corrupt_rejected(
      [](const fs::path& d) { replace_in(d / "frames.csv", "depth/000001.png", "../000001.png"); },
      "frames.csv", "line 3: field depth");
  expect_corrupt_rejected([](const fs::path& d) { fs::remove(d / "depth/000000.png"); },
                          "depth/000000.png", "missing (referenced by");
  expect_corrupt_rejected([](const fs::path& d) { fs::remove(d / "confidence/000002.png"); },
                          "confidence/000002.png", "frames.csv line 4");
  expect_corrupt_rejected(
      [](const fs::path& d) {  // finalized, yet a row less than frame_count
        std::string csv = slurp(d / "frames.csv");
        csv.erase(csv.rfind('\n', csv.size() - 2) + 1);
        spit(d / "frames.csv", csv);
      },
      "frames.csv", "frame_count 3");
  expect_corrupt_rejected(
      [](const fs::path& d) {  // finalized, yet a partial last line
        std::string csv = slurp(d / "frames.csv");
        csv.pop_back();
        spit(d / "frames.csv", csv);
      },
      "frames.csv", "line 4: last line is incomplete");
  expect_corrupt_rejected(
      [](const fs::path& d) {  // an 8-bit PNG where depth belongs
        cv::imwrite((d / "depth/000001.png").string(), cv::Mat(12, 16, CV_8UC1, cv::Scalar(7)));
      },
      "depth/000001.png", "8-bit grayscale");
  expect_corrupt_rejected(
      [](const fs::path& d) {  // a 3-channel 16-bit PNG
        cv::imwrite((d / "depth/000001.png").string(), cv::Mat(12, 16, CV_16UC3, cv::Scalar(7)));
      },
      "depth/000001.png", "16-bit RGB");
  expect_corrupt_rejected(
      [](const fs::path& d) {  // right format, wrong size
        cv::imwrite((d / "depth/000002.png").string(), cv::Mat(10, 16, CV_16UC1, cv::Scalar(7)));
      },
      "depth/000002.png", "is 16x10, expected 16x12");
  expect_corrupt_rejected(
      [](const fs::path& d) {  // a PNG header lying about its size (session says the same)
        std::string png = slurp(d / "depth/000001.png");
        const char big[4] = {0, 0, 0x75, 0x30};  // 30000, big-endian
        png.replace(16, 4, big, 4);
        png.replace(20, 4, big, 4);
        spit(d / "depth/000001.png", png);
        replace_in(d / "session.json", "\"width\": 16", "\"width\": 30000");
        replace_in(d / "session.json", "\"height\": 12", "\"height\": 30000");
      },
      "depth/000000.png", "is 16x12, expected 30000x30000");
  expect_corrupt_rejected(
      [](const fs::path& d) {  // the same lie, consistent with the session: refused unread
        for (const char* f : {"depth/000000.png", "depth/000001.png", "depth/000002.png"}) {
          std::string png = slurp(d / f);
          const char side[4] = {0, 0, 0x20, 0x00};  // 8192 x 8192 = 2^26 pixels, 128 MiB raw
          png.replace(16, 4, side, 4);
          png.replace(20, 4, side, 4);
          spit(d / f, png);
        }
        replace_in(d / "session.json", "\"width\": 16", "\"width\": 8192");
        replace_in(d / "session.json", "\"height\": 12", "\"height\": 8192");
      },
      "depth/000000.png", "far more than");
  expect_corrupt_rejected(
      [](const fs::path& d) {  // truncated PNG data
        std::string png = slurp(d / "depth/000001.png");
        spit(d / "depth/000001.png", png.substr(0, png.size() / 2));
      },
      "depth/000001.png", "frames.csv line 3");
  expect_corrupt_rejected(
      [](const fs::path& d) {
        spit(d / "confidence/000000.png", "GIF89a not a png at all.......");
      },
      "confidence/000000.png", "PNG");
}

}  // namespace
}  // namespace scanclean

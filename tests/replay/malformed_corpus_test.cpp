// The replay readers on the malformed corpus (tests/data/malformed): session.json, frames.csv,
// colour images of a recording, depth images and their intrinsics.json sidecar each give their
// expected error (type and message fragment).

#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <sstream>

#include "replay_fixtures.h"
#include "scanclean/replay/depth_image_source.h"
#include "scanclean/replay/recording_reader.h"
#include "scanclean/replay/recording_writer.h"
#include "support/data_paths.h"
#include "support/malformed_corpus.h"

namespace scanclean {
namespace {

namespace fs = std::filesystem;

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

//! A finalized one-frame recording (16 x 12) in a fresh folder.
fs::path one_frame_recording() {
  const fs::path dir = test::make_temp_dir("malformed") / "rec";
  const SessionMetadata s = test::fixture_session();
  RecordingWriter w(dir, s);
  w.write(test::fixture_frame(s, 0, false));
  w.finish();
  return dir;
}

//! Runs the reader the file's kind calls for; returns {type, message} of the error.
std::pair<std::string, std::string> error_of(const test::MalformedCase& c) {
  const fs::path file = test::malformed_dir() / c.file;
  try {
    if (c.file.rfind("session_", 0) == 0) {
      const fs::path rec = one_frame_recording();
      fs::copy_file(file, rec / "session.json", fs::copy_options::overwrite_existing);
      RecordingReader reader(rec);
    } else if (c.file.rfind("frames_", 0) == 0) {
      const fs::path rec = one_frame_recording();
      fs::copy_file(file, rec / "frames.csv", fs::copy_options::overwrite_existing);
      RecordingReader reader(rec);
      for (std::size_t i = 0; i < reader.frame_count(); ++i) reader.read_frame(i);
    } else if (c.file.rfind("color_", 0) == 0) {
      const fs::path rec = one_frame_recording();
      fs::copy_file(file, rec / c.file);
      std::string csv = slurp(rec / "frames.csv");
      const auto row = csv.find("depth/");
      const auto colour = csv.find(',', row) + 1;  // the (empty) colour column
      csv.insert(colour, c.file);
      std::ofstream(rec / "frames.csv", std::ios::binary | std::ios::trunc) << csv;
      RecordingReader reader(rec);
      reader.read_color(0);
    } else {
      DepthImageOptions o;
      fs::path source = file;
      if (c.file.rfind("intrinsics_", 0) == 0) {
        const fs::path rec = one_frame_recording();
        source = rec.parent_path() / "images";
        fs::create_directories(source);
        fs::copy_file(rec / "depth" / "000000.png", source / "000000.png");
        fs::copy_file(file, source / "intrinsics.json");
      } else {
        Intrinsics K;
        K.fx = K.fy = 500;
        K.cx = K.cy = 1;
        o.K = K;
      }
      auto src = make_depth_image_source(source, o);
      src->open();
      RangeFrame frame;
      const ReadStatus st = src->next(frame, std::chrono::milliseconds(0));
      if (st == ReadStatus::kError) throw InputError(src->last_error());
    }
  } catch (const std::exception& e) {
    return {test::error_type(e), e.what()};
  }
  return {"", ""};
}

TEST(MalformedCorpusTest, EveryRecordingAndImageFileGivesItsExpectedError) {
  const auto cases =
      test::malformed_cases({"session_", "frames_", "color_", "depth_", "intrinsics_"});
  ASSERT_GE(cases.size(), 20u) << "EXPECTED.tsv missing or short in " << test::malformed_dir();
  for (const auto& c : cases) {
    const auto [type, message] = error_of(c);
    EXPECT_EQ(type, c.type) << c.file << ": " << (message.empty() ? "no error" : message);
    EXPECT_NE(message.find(c.fragment), std::string::npos)
        << c.file << ": expected \"" << c.fragment << "\" in: " << message;
  }
}

}  // namespace
}  // namespace scanclean

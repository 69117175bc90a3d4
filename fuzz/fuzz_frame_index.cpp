// libFuzzer target: a recording folder's frame index (frames.csv) on arbitrary bytes, with a
// valid session.json and one valid 4x3 depth PNG (depth/000000.png); every frame the index
// names is decoded.
#include <cstddef>
#include <cstdint>
#include <fstream>

#include "fuzz_support.h"
#include "scanclean/core/errors.h"
#include "scanclean/replay/recording_format.h"
#include "scanclean/replay/recording_reader.h"

namespace {

// A 4x3 16-bit grayscale PNG (all pixels 1000).
const unsigned char kDepthPng[] = {
#include "seeds/depth4x3_png.inc"
};

const std::filesystem::path& folder() {
  static const std::filesystem::path dir = [] {
    const auto d = scanclean::fuzz::temp_dir() / "rec";
    std::filesystem::create_directories(d / "depth");
    std::ofstream(d / "depth" / "000000.png", std::ios::binary)
        .write(reinterpret_cast<const char*>(kDepthPng), sizeof kDepthPng);
    scanclean::SessionMetadata s;
    s.width = 4;
    s.height = 3;
    s.unit_m = 0.001;
    s.K.fx = s.K.fy = 5;
    s.K.cx = 2;
    s.K.cy = 1.5;
    s.K.width = 4;
    s.K.height = 3;
    scanclean::write_session(d, s);
    return d;
  }();
  return dir;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto& dir = folder();
  std::ofstream(dir / "frames.csv", std::ios::binary | std::ios::trunc)
      .write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  try {
    scanclean::RecordingReader reader(dir);
    for (std::size_t i = 0; i < reader.frame_count() && i < 4; ++i) {
      SCANCLEAN_FUZZ_EXPECTED_ERRORS(reader.read_frame(i));
    }
  } catch (const scanclean::Error&) {
  }
  return 0;
}

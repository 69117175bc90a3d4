// libFuzzer target: the intrinsics.json sidecar of depth images, on arbitrary bytes, beside one
// valid 4x3 depth PNG (no intrinsics on the command line, so the sidecar is read).
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <fstream>

#include "fuzz_support.h"
#include "scanclean/core/errors.h"
#include "scanclean/core/range_frame.h"
#include "scanclean/replay/depth_image_source.h"

namespace {
const unsigned char kDepthPng[] = {
#include "seeds/depth4x3_png.inc"
};
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::filesystem::path dir = [] {
    const auto d = scanclean::fuzz::temp_dir() / "images";
    std::filesystem::create_directories(d);
    std::ofstream(d / "000000.png", std::ios::binary)
        .write(reinterpret_cast<const char*>(kDepthPng), sizeof kDepthPng);
    return d;
  }();
  std::ofstream(dir / "intrinsics.json", std::ios::binary | std::ios::trunc)
      .write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  try {
    auto source = scanclean::make_depth_image_source(dir, scanclean::DepthImageOptions{});
    source->open();
    scanclean::RangeFrame frame;
    (void)source->next(frame, std::chrono::milliseconds(0));
    source->close();
  } catch (const scanclean::Error&) {
  }
  return 0;
}

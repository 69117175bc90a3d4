// libFuzzer target: one depth image (PNG16, PGM, TIFF; the first byte picks the extension)
// read as a depth-image source with given intrinsics: open(), then every frame.
#include <chrono>
#include <cstddef>
#include <cstdint>

#include "fuzz_support.h"
#include "scanclean/core/errors.h"
#include "scanclean/core/range_frame.h"
#include "scanclean/replay/depth_image_source.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  static const char* const kExt[] = {".png", ".pgm", ".tif", ".tiff"};
  const char* ext = kExt[data[0] % 4];
  const auto path = scanclean::fuzz::write_input(std::string("depth") + ext, data + 1, size - 1);
  scanclean::DepthImageOptions o;
  scanclean::Intrinsics K;
  K.fx = K.fy = 500;
  K.cx = K.cy = 1;
  o.K = K;
  try {
    auto source = scanclean::make_depth_image_source(path, o);
    source->open();
    scanclean::RangeFrame frame;
    for (int i = 0; i < 2; ++i)
      if (source->next(frame, std::chrono::milliseconds(0)) != scanclean::ReadStatus::kOk) break;
    source->close();
  } catch (const scanclean::Error&) {
  }
  return 0;
}

// libFuzzer target: a recording's colour image (PNG, JPEG or PPM; the first byte picks the
// extension) through the reader RecordingReader::read_color uses.
#include <cstddef>
#include <cstdint>

#include "fuzz_support.h"
#include "png16.h"
#include "scanclean/core/errors.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  static const char* const kExt[] = {".png", ".jpg", ".ppm"};
  const char* ext = kExt[data[0] % 3];
  const auto path = scanclean::fuzz::write_input(std::string("color") + ext, data + 1, size - 1);
  SCANCLEAN_FUZZ_EXPECTED_ERRORS(scanclean::detail::read_rgb_image(path));
  return 0;
}

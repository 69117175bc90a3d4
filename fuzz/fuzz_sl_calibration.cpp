// libFuzzer target: the structured-light calibration parser (the project's calib.yml and the
// kamino410 XML layout) on arbitrary bytes. The parser reads the text itself; OpenCV's
// FileStorage never sees untrusted bytes. Seeds: both layouts as `scanclean sl calibrate` writes
// them.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "fuzz_support.h"
#include "scanclean/core/errors.h"
#include "scanclean/drivers/sl_calibration.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  SCANCLEAN_FUZZ_EXPECTED_ERRORS((void)scanclean::parse_sl_calibration(text, "fuzz input"));
  return 0;
}

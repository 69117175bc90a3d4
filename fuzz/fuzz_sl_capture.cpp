// libFuzzer target: the structured-light capture description (capture.json) on arbitrary bytes,
// through the same parser describe_sl_capture() uses after reading the file. Seeds: a full
// description of a 1024x768 projector and a minimal one.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "fuzz_support.h"
#include "scanclean/core/errors.h"
#include "scanclean/drivers/sl_capture.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  SCANCLEAN_FUZZ_EXPECTED_ERRORS(
      (void)scanclean::parse_sl_capture_description(text, "fuzz/capture.json"));
  return 0;
}

// libFuzzer target: session.json of a recording folder (session_from_json) on arbitrary bytes.
#include <cstddef>
#include <cstdint>
#include <string>

#include "fuzz_support.h"
#include "scanclean/core/errors.h"
#include "scanclean/replay/recording_format.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  SCANCLEAN_FUZZ_EXPECTED_ERRORS(scanclean::session_from_json(text, "session.json"));
  return 0;
}

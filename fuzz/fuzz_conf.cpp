// libFuzzer target: read_conf() (Stanford .conf scan session) on arbitrary bytes.
#include <cstddef>
#include <cstdint>

#include "fuzz_support.h"
#include "scanclean/core/errors.h"
#include "scanclean/io/stanford_conf.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = scanclean::fuzz::write_input("in.conf", data, size);
  scanclean::ReadReport report;
  SCANCLEAN_FUZZ_EXPECTED_ERRORS(scanclean::read_conf(path, &report));
  return 0;
}
